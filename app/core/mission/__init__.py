"""The mission state machine, pure: the agent step, the ground station step, the stages."""
