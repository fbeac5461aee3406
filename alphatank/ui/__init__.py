"""Presentation: the pygame renderer, keyboard players, match videos and replays."""
