"""Bus factory: each backend by config, clear errors for what cannot be opened."""

from __future__ import annotations

import can
import pytest

from com3_can.bus import link_config, load_bus_config, open_bus, socketcan_available
from com3_can.errors import Com3BusError
from tms_common.errors import ConfigError


def test_virtual_bus_round_trip() -> None:
    a = open_bus({"interface": "virtual", "channel": "com3_test_virtual"})
    b = open_bus({"interface": "virtual", "channel": "com3_test_virtual"})
    try:
        a.send(can.Message(arbitration_id=0x18FF670A, data=bytes.fromhex("c87d707b007de880"), is_extended_id=True))
        msg = b.recv(1.0)
        assert msg is not None and msg.arbitration_id == 0x18FF670A and bytes(msg.data).hex() == "c87d707b007de880"
    finally:
        a.shutdown()
        b.shutdown()


def test_config_errors_name_the_culprit() -> None:
    with pytest.raises(
        ConfigError, match=r"CAN interface 'pcan' unknown; expected one of socketcan, udp_multicast, virtual"
    ):
        open_bus({"interface": "pcan", "channel": "x"})
    with pytest.raises(ConfigError, match="'channel' is required"):
        open_bus({"interface": "virtual"})
    with pytest.raises(ConfigError, match=r"unknown option\(s\) \['bitrate'\]"):
        open_bus({"interface": "udp_multicast", "channel": "239.74.163.9", "bitrate": 500000})


def test_socketcan_absent_or_missing_interface_is_explained() -> None:
    if socketcan_available():
        with pytest.raises(Com3BusError, match="'nocan9' does not exist"):
            open_bus({"interface": "socketcan", "channel": "nocan9"})
    else:
        with pytest.raises(Com3BusError, match="SocketCAN is not available in this kernel"):
            open_bus({"interface": "socketcan", "channel": "vcan0"})


@pytest.mark.parametrize("machine", ["zx200", "ic120"])
def test_shipped_bus_configs_are_valid(machine: str) -> None:
    cfg = load_bus_config(machine)
    assert cfg["interface"] in ("socketcan", "udp_multicast", "virtual") and cfg["channel"]
    assert "bridge" in cfg


def _bus_file(tmp_path, text: str):
    path = tmp_path / "zx200.yaml"
    path.write_text(text)
    return path


def test_an_option_the_bus_refuses_names_its_file_and_line(tmp_path) -> None:
    """What config/can/<kind>.yaml gives travels with the options: open_bus names the file and line to fix."""
    path = _bus_file(tmp_path, "# a bus\ninterface: pcan\nchannel: x\n")
    with pytest.raises(ConfigError, match=rf"^{path}:2: interface: CAN interface 'pcan' unknown"):
        open_bus(link_config("zx200", load_bus_config("zx200", path)))
    path = _bus_file(tmp_path, "interface: virtual\nchannel: com3_test_line\nhop_limit: 2\n")
    with pytest.raises(ConfigError, match=rf"^{path}:3: hop_limit: CAN virtual: unknown option\(s\) \['hop_limit'\]"):
        open_bus(link_config("zx200", load_bus_config("zx200", path)))
    # an override names the node parameter, not the file
    with pytest.raises(ConfigError, match=r"^the interface given by a node parameter: interface: CAN interface"):
        open_bus(link_config("zx200", load_bus_config("zx200", path), interface="pcan"))


def test_a_bad_bus_file_is_refused_where_it_is_read(tmp_path) -> None:
    path = _bus_file(tmp_path, "interface: udp_multicast\nchannel: 239.74.163.9\nbitrate: 500000\n")
    with pytest.raises(ConfigError, match=rf"^{path}:3: bitrate: unknown key"):
        load_bus_config("zx200", path)
    path = _bus_file(tmp_path, "interface: udp_multicast\nchannel: [239, 74]\n")
    with pytest.raises(ConfigError, match=rf"^{path}:2: channel: expected a non-empty string"):
        load_bus_config("zx200", path)
