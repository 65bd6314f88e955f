"""Parameters from measurements: fit scenario parameters to measured records.

::

    from braidsim.fit import fit
    res = fit("paper-3.1", "record.csv",
              free={"contact.track.restitution": [0.2, 0.95], "track.clearance": ["2 mm", "4 mm"]},
              quantity="acceleration")
    res.values, res.stats.stderr, res.stats.ci95, res.warnings

The spec file of ``braidsim fit`` (:mod:`braidsim.fit.spec`), the records it reads
(:mod:`braidsim.fit.data`), the residuals and Jacobians (:mod:`braidsim.fit.problem`), the
estimation (:mod:`braidsim.fit.estimate`) and the report (:mod:`braidsim.fit.report`).
"""

from braidsim.fit.data import QUANTITY_UNITS, Record, make_record, read_record
from braidsim.fit.estimate import FitResult, fit, fit_record
from braidsim.fit.problem import Problem
from braidsim.fit.spec import FitSpec, FreeParameter, load_fit_spec, parse_fit_spec
from braidsim.fit.synthetic import synthetic_record

__all__ = [
    "QUANTITY_UNITS",
    "FitResult",
    "FitSpec",
    "FreeParameter",
    "Problem",
    "Record",
    "fit",
    "fit_record",
    "load_fit_spec",
    "make_record",
    "parse_fit_spec",
    "read_record",
    "synthetic_record",
]
