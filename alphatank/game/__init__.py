"""The agent-facing layer over the simulation: scenarios (who sits where), seats and their
controller kinds, line-ups and the arena (one game per scenario and seed), observations
and rewards."""
