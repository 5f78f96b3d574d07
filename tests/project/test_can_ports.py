"""The test harness's CAN port choice passes over ports a left-over process still holds."""

from __future__ import annotations

import socket

import pytest

from tests.rosproc import CAN_PORTS_PER_DOMAIN, can_port, free_can_ports, isolated_domain


def _hold(port: int) -> socket.socket:
    """Bind ``port`` the way python-can's udp_multicast bus does (SO_REUSEADDR + SO_REUSEPORT)."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)
    sock.bind(("", port))
    return sock


def test_free_can_ports_skip_held_ports_and_fail_when_too_few_are_left():
    with isolated_domain() as domain:
        held = [_hold(can_port(domain, k)) for k in range(CAN_PORTS_PER_DOMAIN - 2)]
        try:
            ports = free_can_ports(domain, 2)
            assert sorted(ports) == [
                can_port(domain, CAN_PORTS_PER_DOMAIN - 2),
                can_port(domain, CAN_PORTS_PER_DOMAIN - 1),
            ]
            with pytest.raises(RuntimeError, match="only 2 of domain"):
                free_can_ports(domain, 3)
        finally:
            for sock in held:
                sock.close()
        assert len(set(free_can_ports(domain, CAN_PORTS_PER_DOMAIN))) == CAN_PORTS_PER_DOMAIN
