"""The default ``osqp_piqp`` back-end: OSQP first, PIQP when OSQP has not converged."""

from __future__ import annotations

from typing import Any

import numpy as np

from controllers.mpc.backends.conic import ConicBackend
from controllers.mpc.backends.osqp_direct import OSQPBackend
from controllers.mpc.problem import QPBuilder

#: OSQP's iteration cap before the same QP goes to PIQP.
OSQP_MAX_ITER = 60


class HybridBackend:
    """OSQP first (cheap when few constraints are active, warm-started); when it does not reach
    ``solved`` within ``osqp_max_iter`` iterations (it stalls when many velocity / position
    limits are active at once), the same QP is re-solved by PIQP (a proximal interior-point
    method whose iteration count hardly depends on the active set).

    Attributes:
        osqp, piqp: the two back-ends.
        piqp_calls: solves that went to PIQP.
    """

    def __init__(self, qp: QPBuilder, options: dict[str, Any]) -> None:
        osqp_opts = {"max_iter": OSQP_MAX_ITER, **options}
        self.osqp = OSQPBackend(qp, osqp_opts)
        self.piqp = ConicBackend(qp, "piqp", {})
        self.piqp_calls = 0

    def solve(self, p: np.ndarray) -> tuple[np.ndarray, bool]:
        """The QP at parameter vector ``p``: ``(z, ok)``."""
        x, ok = self.osqp.solve(p)
        if ok and self.osqp.last_status == 1:
            return x, True
        self.piqp_calls += 1
        return self.piqp.solve(p)
