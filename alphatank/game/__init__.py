"""The agent-facing layer over the simulation: scenarios (who sits where), observations
and rewards."""
