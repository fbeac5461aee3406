"""Map generation, lint and editing (the logic behind ``tools/mapgen.py``)."""

from alphatank.mapgen.generate import (
    ALGORITHMS,
    SYMMETRIES,
    GenOptions,
    MapGenError,
    check_name,
    generate,
    generate_from,
    map_variants,
)
from alphatank.mapgen.lint import MapWarning, ascii_art, check_map, describe, map_warnings
from alphatank.mapgen.model import EditorModel

__all__ = ["ALGORITHMS", "SYMMETRIES", "EditorModel", "GenOptions", "MapGenError",
           "MapWarning", "ascii_art", "check_map", "check_name", "describe", "generate",
           "generate_from", "map_variants", "map_warnings"]
