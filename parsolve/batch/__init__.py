"""Many runs of a scene, locally or as a SLURM job array: ``parsolve batch JOBS.toml``.

The Python API (used by ``parsolve study``): ``Run``, ``Outcome``, ``execute``, ``outcomes``
and ``effective_scene`` (a base scene with values replaced by dotted paths)."""

from parsolve.batch.api import Outcome, Run, execute, outcomes
from parsolve.batch.scene_edit import effective_scene

__all__ = ["Outcome", "Run", "effective_scene", "execute", "outcomes"]
