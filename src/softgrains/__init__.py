"""softgrains: implicit MPM with Contact Dynamics for assemblies of highly deformable grains.

    import softgrains as sg
    case = sg.load_case("examples/free_disk.toml", overrides={"simulation.dt": 1e-4})
    sim = sg.Simulation(case, out="results/run1")
    sim.run()
"""

from softgrains.threads import set_wait_policy

set_wait_policy()  # before any parallel kernel loads the OpenMP runtime (threads.py)

from softgrains.case import Case, load_case  # noqa: E402
from softgrains.errors import CaseError, SimulationError  # noqa: E402
from softgrains.simulation import Simulation  # noqa: E402

__version__ = "0.1.0"
__all__ = ["Case", "CaseError", "Simulation", "SimulationError", "__version__", "load_case", "run"]


def run(case_path, out=None, overrides=None) -> dict:
    """Load a case file, run it and return the summary."""
    return Simulation(load_case(case_path, overrides), out=out).run()
