"""Presentation: the pygame renderer, keyboard players, match videos and replays, and the
interactive play session."""
