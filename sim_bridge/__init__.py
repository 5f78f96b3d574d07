"""sim_bridge: the site in simulation.

A MuJoCo plant of the machines a plant YAML names (the paper's ZX200 and IC120, or any machines of a known
type) with hydraulic actuator dynamics and a soil mound, driven only through COM3 CAN frames as the real
machines are. It publishes ``/clock`` so the whole stack can run
on simulated time, and ground truth under ``/sim/truth`` for evaluation only.
"""
