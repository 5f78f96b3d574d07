"""The report's replay page (tms_ur.replay_page): a rosbag2 recording written with tms_ur.recording (two machines
moving on known paths, a bucket tip, soil totals, a carrier's load) becomes replay.html; headless chromium moves the
time slider (keyboard on the range input) and reads what the page drew: each machine at the recorded pose of the
slider's time, its canvas position moving the way the machine moved. Plus the timeline itself and the errors."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from geometry_msgs.msg import PointStamped, PoseStamped
from rclpy.serialization import serialize_message
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from tms_model.site import load_site
from tms_ur.experiment_core import ExperimentRecorder
from tms_ur.recording import BagRecorder
from tms_ur.replay_page import ReplayError, main, replay_timeline, write_replay

T0 = 500.0  # log time of the first message [s of simulated time]
N = 100  # samples per machine, 10 Hz over 10 s


def _pose(x: float, y: float, yaw: float) -> bytes:
    m = PoseStamped()
    m.header.frame_id = "map"
    m.pose.position.x, m.pose.position.y = x, y
    m.pose.orientation.z, m.pose.orientation.w = math.sin(yaw / 2), math.cos(yaw / 2)
    return serialize_message(m)


def _array(labels: list[str], values: list[float]) -> bytes:
    msg = Float64MultiArray(data=values)
    msg.layout.dim = [MultiArrayDimension(label=",".join(labels), size=len(values))]
    return serialize_message(msg)


def zx200_at(i: int) -> tuple[float, float, float]:
    return 10.0 + 0.2 * i, 5.0, 0.01 * i


def ic120_at(i: int) -> tuple[float, float, float]:
    return 30.0, 8.0 + 0.3 * i, -0.02 * i


@pytest.fixture
def run_dir(tmp_path: Path) -> Path:
    run = tmp_path / "run"
    run.mkdir()
    rec = BagRecorder(run / "bag")
    for topic, msgtype in (("/sim/truth/zx200/pose", "geometry_msgs/msg/PoseStamped"),
                           ("/sim/truth/ic120/pose", "geometry_msgs/msg/PoseStamped"),
                           ("/sim/truth/zx200/bucket_tip", "geometry_msgs/msg/PointStamped"),
                           ("/sim/truth/soil", "std_msgs/msg/Float64MultiArray"),
                           ("/sim/truth/ic120/soil", "std_msgs/msg/Float64MultiArray"),
                           ("/tf", "tf2_msgs/msg/TFMessage")):
        rec.add_topic(topic, msgtype)
    for i in range(N):
        ns = int((T0 + 0.1 * i) * 1e9)
        rec.write("/sim/truth/zx200/pose", ns, _pose(*zx200_at(i)))
        rec.write("/sim/truth/ic120/pose", ns + 1000, _pose(*ic120_at(i)))
        tip = PointStamped()
        tip.point.x, tip.point.y, tip.point.z = 15.0, 6.0 + 0.01 * i, 1.0
        rec.write("/sim/truth/zx200/bucket_tip", ns + 2000, serialize_message(tip))
        rec.write("/sim/truth/soil", ns + 3000, _array(["mound", "bucket", "vessel", "dumped"],
                                                       [20.0 - 0.01 * i, 0.5, 0.01 * i, 0.0]))
        rec.write("/sim/truth/ic120/soil", ns + 4000, _array(["vessel", "loaded", "dumped"], [0.02 * i, 0.0, 0.0]))
    rec.close()
    return run


def test_timeline(run_dir: Path) -> None:
    tl = replay_timeline(run_dir / "bag", rate_hz=5.0)
    assert tl["t0"] == pytest.approx(T0) and tl["t1"] == pytest.approx(T0 + 0.1 * (N - 1), abs=1e-3)
    zx = tl["machines"]["zx200"]
    assert len(zx) == N // 2  # 10 Hz recorded, 5 Hz kept
    t, x, y, yaw = zx[10]  # the 11th kept sample is recorded sample 20
    assert t == pytest.approx(T0 + 2.0) and (x, y) == pytest.approx(zx200_at(20)[:2]) and yaw == pytest.approx(0.2)
    assert set(tl["machines"]) == {"zx200", "ic120"} and list(tl["tips"]) == ["zx200"]
    assert tl["soil"][0][1] == {"mound": 20.0, "bucket": 0.5, "vessel": 0.0, "dumped": 0.0}
    assert tl["carrier_soil"]["ic120"][5][1] == pytest.approx(0.2)


def test_replay_page_slider_in_chromium(run_dir: Path, browser_page) -> None:
    # the report links the replay when the run has a recording
    ExperimentRecorder().report(run_dir, site=load_site(), machines=[])
    assert 'href="replay.html"' in (run_dir / "index.html").read_text()
    page_path = write_replay(run_dir)
    html = page_path.read_text()
    assert "http://" not in html and "https://" not in html  # nothing fetched: no CDN
    page = browser_page
    page.goto(page_path.as_uri())
    drawn = page.evaluate("window.replayDrawn")
    assert drawn["t"] == pytest.approx(T0)
    assert (drawn["machines"]["zx200"]["x"], drawn["machines"]["zx200"]["y"]) == pytest.approx(zx200_at(0)[:2])
    slider = page.locator("#slider")
    slider.focus()
    seen = []
    for presses in (20, 35):  # step 0.1 s per ArrowRight
        for _ in range(presses):
            page.keyboard.press("ArrowRight")
        drawn = page.evaluate("window.replayDrawn")
        t = drawn["t"]
        assert float(slider.input_value()) == pytest.approx(t)
        i = round((t - T0) / 0.1)
        kept = i - i % 2  # 5 Hz kept: the last kept sample at or before t
        for name, truth in (("zx200", zx200_at), ("ic120", ic120_at)):
            m = drawn["machines"][name]
            assert m["stamp"] <= t + 1e-6
            assert (m["x"], m["y"], m["yaw"]) == pytest.approx(truth(kept), abs=1e-3), (name, t, m)
        seen.append(drawn)
    assert seen[0]["t"] == pytest.approx(T0 + 2.0) and seen[1]["t"] == pytest.approx(T0 + 5.5)
    # on the canvas: the ZX200 moved right (+x), the IC120 up (+y: canvas y decreases)
    a, b = seen[0]["machines"], seen[1]["machines"]
    assert b["zx200"]["px"] > a["zx200"]["px"] + 5 and abs(b["zx200"]["py"] - a["zx200"]["py"]) < 1e-6
    assert b["ic120"]["py"] < a["ic120"]["py"] - 5
    text = page.locator("#soil").inner_text()  # at t0 + 5.5 s: the kept sample 54
    assert "vessel 0.54" in text and "vessels: ic120 1.08" in text, text
    page.keyboard.press("End")
    assert page.evaluate("window.replayDrawn")["t"] == pytest.approx(T0 + 0.1 * (N - 1), abs=0.06)


def test_replay_errors(tmp_path: Path, run_dir: Path, capsys) -> None:
    with pytest.raises(ReplayError, match=f"no recording {tmp_path / 'bag'}"):
        write_replay(tmp_path)
    assert main([str(tmp_path)]) == 2 and "no recording" in capsys.readouterr().err
    only_tf = tmp_path / "tf_only"
    only_tf.mkdir()
    rec = BagRecorder(only_tf / "bag")
    rec.add_topic("/tf", "tf2_msgs/msg/TFMessage")
    rec.close()
    with pytest.raises(ReplayError, match="no /sim/truth/<machine>/pose topic"):
        write_replay(only_tf)
    assert not (only_tf / "replay.html").exists()
    assert main([str(run_dir)]) == 0 and (run_dir / "replay.html").is_file()
