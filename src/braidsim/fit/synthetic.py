"""Synthetic records: what a sensor on the simulated carrier would record.

Used to plan a measurement (is a parameter identifiable from this sensor, at this rate and
noise?), in the tests (records with known truth) and in the example.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from braidsim.errors import InputError
from braidsim.fit.data import QUANTITY_UNITS, Record, make_record
from braidsim.params import Scenario, load_scenario


def synthetic_record(
    scenario: Scenario | str,
    duration: float,
    rate: float = 10_000.0,
    noise: Mapping[str, float] | None = None,
    quantities: Sequence[str] = ("acceleration",),
    seed: int | np.random.Generator | None = 0,
    overrides: Mapping[str, Any] | None = None,
) -> Record:
    """Sample the simulated carrier at ``rate`` [Hz] from t = 1/rate to ``duration`` [s]
    and add white Gaussian noise of standard deviation ``noise[q]`` [SI] (none where absent).

    The samples are instantaneous values (an ideal anti-aliased sensor would low-pass them;
    a fit of such a record must filter the model the same way).
    """
    from braidsim.fit.problem import predict
    from braidsim.simulate import simulate

    sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    if overrides:
        sc = sc.with_overrides(overrides)
    if not (rate > 0 and duration * rate >= 3):
        raise InputError(f"rate: {rate:g} Hz gives fewer than 3 samples in {duration:g} s")
    n = int(np.floor(duration * rate + 1e-9))
    t = np.arange(1, n + 1) / rate
    res = simulate(sc, duration=float(t[-1]), sample_times=t, record_events=False)
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    cols = {}
    for q in quantities:
        if q not in QUANTITY_UNITS:
            raise InputError(
                f"quantities: {q!r} is not allowed; allowed {', '.join(QUANTITY_UNITS)}"
            )
        y = predict(res, q)
        s = (noise or {}).get(q, 0.0)
        cols[q] = y + rng.normal(0.0, s, y.size) if s > 0 else y
    return make_record(t, cols, source=f"synthetic {sc.name}")
