"""``sctd eval``: assistance measured with the simulated user, in lockstep or real time."""
