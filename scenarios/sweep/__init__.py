"""The study (``python -m scenarios.sweep``): the grid and its runs (``study``), the tables and paired tests
(``tables``), the figures (``figures``) and the report (``report``)."""

from scenarios.sweep.study import (AXES, FAMILIES, LEADS, PERCEPTIONS, STEP_S, Study, cell_key, default_grid, main,
                                   run_cell, run_local, run_ray, write_csv)

__all__ = ["AXES", "FAMILIES", "LEADS", "PERCEPTIONS", "STEP_S", "Study", "cell_key", "default_grid", "main", "run_cell",
           "run_local", "run_ray", "write_csv"]
