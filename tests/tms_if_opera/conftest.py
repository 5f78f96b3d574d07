"""The ``arm_stack`` fixture (:mod:`tests.arm_stack`) for this directory's tests of the planner over the whole arm
stack."""

from tests.arm_stack import arm_stack  # noqa: F401 - a fixture, found by pytest through this module

