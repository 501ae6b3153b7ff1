"""Which OpenBLAS kernel numpy's matrix products run on, pinned where results are compared bit for bit.

numpy's wheels bundle OpenBLAS built for many CPUs; at load it picks the kernels of the host (``DYNAMIC_ARCH``). Two
kernels sum a small product in a different order, so the same episode's torques differ in their last bits between a
host with AVX-512 (OpenBLAS's SkylakeX kernels) and one without (Haswell / Zen): measured on 2026-12-06, the golden
CI subset's 4 MPC episodes moved by 1e-14 m on an AVX-512 EPYC against the record made on an AVX2 one, and were
identical again with ``OPENBLAS_CORETYPE=Haswell``. The golden record (``scenarios.golden``) and the tests therefore
run on the Haswell kernels, which every x86-64 host with AVX2 has. The variable is read once, when numpy loads
OpenBLAS: it must be set before numpy is imported (``tests/conftest.py``; ``golden`` re-executes itself with it).
"""

from __future__ import annotations

import platform
from collections.abc import MutableMapping

#: the kernel family the golden record was made on (AVX2: any x86-64 host of the last decade)
PINNED_CORETYPE = "Haswell"
VARIABLE = "OPENBLAS_CORETYPE"


def pin_blas_kernel(environ: MutableMapping[str, str]) -> bool:
    """Set ``OPENBLAS_CORETYPE`` in ``environ`` to :data:`PINNED_CORETYPE` on x86-64 unless the user set it; returns
    whether ``environ`` now names the pinned kernel (False elsewhere: other architectures have no such choice)."""
    if platform.machine().lower() not in ("x86_64", "amd64"):
        return False
    environ.setdefault(VARIABLE, PINNED_CORETYPE)
    return environ[VARIABLE] == PINNED_CORETYPE
