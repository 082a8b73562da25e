"""Case dictionaries shared by the case-layer tests."""


def minimal_case() -> dict:
    """The smallest valid case: one disk in a 1 m square."""
    return {
        "simulation": {"dt": 1e-3, "end_time": 0.1},
        "grid": {"cell_size": 0.05, "size": [1.0, 1.0]},
        "materials": {"rubber": {"young": 1e6, "poisson": 0.3, "density": 1000.0}},
        "bodies": [{"shape": "disk", "center": [0.5, 0.5], "radius": 0.2, "material": "rubber"}],
    }
