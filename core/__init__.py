"""The standalone render core: numpy, embreex and numba, never bpy.

The core runs its own worker threads (one per core), so BLAS thread pools would only
oversubscribe the machine: unless the environment says otherwise, BLAS and OpenMP are
pinned to one thread here, before numpy is first imported.
"""

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
