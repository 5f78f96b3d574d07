"""``tms_rc_identify`` against a running ``sim_plant`` process over a python-can bus (udp_multicast): a short
identification of the bucket finds the dead time and lag the plant's description gives it, within 30 %.

The test may read the plant's description (the identification and the controller may not): it is the answer.
"""

from __future__ import annotations

import pytest
import yaml

from sim_bridge.config import load_plant
from tests.rosproc import executable, start_private_plant
from tms_common.config import config_path

pytestmark = pytest.mark.integration

JOINT = "bucket_joint"


def test_a_short_identification_of_the_bucket_over_can_finds_the_plants_dead_time_and_lag(procs, domain, tmp_path):
    # the paper plant starts the front in the air (plant.yaml's home pose has the bucket in the mound, where the
    # soil's cutting resistance would enter the figures)
    buses = start_private_plant(procs, domain, config_path('sim', 'paper_plant.yaml'), speed=1.0, group=77)
    out = tmp_path / "zx200.yaml"
    ident = procs([executable("tms_rc", "tms_rc_identify"), "--machine", "zx200", "--can-interface", "udp_multicast",
                   "--can-channel", buses["zx200"]["channel"], "--can-port", str(buses["zx200"]["port"]),
                   "--joints", JOINT, "--amplitudes", "0.1,0.2,0.3", "--chirp-s", "0", "--no-pump",
                   "--output", str(out)],
                  name="tms_rc_identify")
    assert ident.wait(240) == 0, ident.output
    text = out.read_text()
    assert f"--joints {JOINT}" in text.splitlines()[2]  # the command that made it
    figures = yaml.safe_load(text)["joints"][JOINT]
    drive = load_plant(config_path("sim", "paper_plant.yaml")).description("zx200").drives[JOINT]
    # The plant's valve waits its dead time, then its spool lags and the oil column and the bucket's inertia take their
    # share: the first response comes after the dead time (never before it, less the 10 ms frames) and within the
    # spool's settling time of it; the overall lag is at least the spool's
    first = figures["dead_time_s"]
    assert drive.dead_time - 0.02 <= first <= drive.dead_time + 4 * drive.time_constant, (figures, drive)
    assert drive.time_constant * 0.7 <= figures["lag_s"] <= drive.time_constant * 4, (figures, drive)
    assert figures["gain"] == pytest.approx(1.0, rel=0.1)  # velocity mode: the machine's controller meters the speed
