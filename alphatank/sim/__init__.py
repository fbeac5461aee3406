"""The simulation layer: configs, maps and their grid graphs, the pymunk world, match
rules, episodes (the seeding rule and the tick loop with hooks), ballistics and
navigation. Knows nothing of agents, rewards or pygame."""
