"""The simulation layer: configs, maps, the pymunk world, match rules, ballistics and
navigation. Knows nothing of agents, rewards or pygame."""
