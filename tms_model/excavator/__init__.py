"""Excavator kinds (ZX200, ZX120, ...): kinematics built from a description, arm targets, result codes."""
