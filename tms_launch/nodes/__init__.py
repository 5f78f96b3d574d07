"""Demonstration nodes (console scripts ``demo_talker``, ``demo_listener``, ``demo_subtask_server``) for the foundation
tests."""
