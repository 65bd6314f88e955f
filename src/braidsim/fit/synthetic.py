"""Synthetic records: what a sensor on the simulated carrier would record.

Used to plan a measurement (is a parameter identifiable from this sensor, at this rate and
noise?), in the tests (records with known truth) and in the example.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from braidsim.errors import InputError
from braidsim.fit.data import QUANTITY_UNITS, Record, make_record
from braidsim.params import Scenario, load_scenario
from braidsim.units import to_si


def synthetic_record(
    scenario: Scenario | str,
    duration: float | str,
    rate: float | str = 10_000.0,
    noise: Mapping[str, float | str] | None = None,
    quantities: Sequence[str] = ("acceleration",),
    seed: int | np.random.Generator | None = 0,
    overrides: Mapping[str, Any] | None = None,
    time_offset: float | str = 0.0,
) -> Record:
    """Sample the simulated carrier at ``rate`` [Hz] from t = 1/rate to ``duration`` [s]
    and add white Gaussian noise of standard deviation ``noise[q]`` [SI] (none where absent).

    ``time_offset`` [s, >= 0]: the model's time of the record's t = 0 (a sensor triggered
    that late): sample i holds the model at t_i + time_offset, and is stamped t_i
    (the fit's free key ``record.time_offset`` estimates it).

    ``duration``, ``rate`` and the noise levels are numbers in SI or strings with a unit
    (``"30 ms"``, ``"10 kHz"``, ``"20 m/s^2"``); ``noise`` has a key per recorded quantity
    at most (a key of ``quantities``).

    The samples are instantaneous values (an ideal anti-aliased sensor would low-pass them;
    a fit of such a record must filter the model the same way).
    """
    from braidsim.fit.problem import predict
    from braidsim.simulate import simulate, time_value

    sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    if overrides:
        sc = sc.with_overrides(overrides)
    duration = time_value("duration", duration)  # a number in s or a string with a unit
    rate = to_si("rate", rate, "Hz")
    offset = to_si("time_offset", time_offset, "s")
    if not (math.isfinite(offset) and offset >= 0):
        raise InputError(f"time_offset: {offset:g} s is out of range; allowed >= 0 s")
    if not (math.isfinite(rate) and rate > 0):
        raise InputError(f"rate: {rate:g} Hz is out of range; allowed > 0 Hz")
    if not duration * rate >= 3:
        raise InputError(
            f"rate: {rate:g} Hz gives fewer than 3 samples in {duration:g} s; allowed >= "
            f"{3 / duration:g} Hz"
        )
    qs = _quantities(quantities)
    sigma = _noise(noise, qs)
    n = int(np.floor(duration * rate + 1e-9))
    t = np.arange(1, n + 1) / rate
    res = simulate(sc, duration=float(t[-1] + offset), sample_times=t + offset, record_events=False)
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    cols = {}
    for q in qs:
        y = predict(res, q)
        s = sigma.get(q, 0.0)
        cols[q] = y + rng.normal(0.0, s, y.size) if s > 0 else y
    return make_record(t, cols, source=f"synthetic {sc.name}")


def _quantities(quantities: Sequence[str]) -> tuple[str, ...]:
    """The recorded quantities; an InputError unless each is one of :data:`QUANTITY_UNITS`."""
    allowed = ", ".join(QUANTITY_UNITS)
    if isinstance(quantities, str | bytes) or not isinstance(quantities, Sequence):
        raise InputError(
            f"quantities: {quantities!r} is not a list of quantities; allowed a list of "
            f"{allowed}, e.g. ['acceleration']"
        )
    for q in quantities:
        if q not in QUANTITY_UNITS:
            raise InputError(f"quantities: {q!r} is not allowed; allowed {allowed}")
    return tuple(quantities)


def _noise(noise: Mapping[str, float | str] | None, quantities: Sequence[str]) -> dict[str, float]:
    """The noise levels [SI] by recorded quantity; an InputError naming an unknown or
    unrecorded key (with the closest recorded one) or a level that is not >= 0."""
    if noise is None:
        return {}
    if not isinstance(noise, Mapping):
        raise InputError(
            f"noise: {noise!r} is not a mapping; allowed {{quantity: standard deviation}}, "
            "e.g. {'acceleration': 20.0}"
        )
    out = {}
    for key, value in noise.items():
        if key not in quantities:
            near = difflib.get_close_matches(str(key), list(quantities), n=1)
            hint = f" (did you mean {near[0]!r}?)" if near else ""
            what = (
                "is not recorded (add it to quantities)"
                if key in QUANTITY_UNITS
                else ("is not a known quantity")
            )
            raise InputError(f"noise: {key!r} {what}{hint}; allowed keys {', '.join(quantities)}")
        unit = QUANTITY_UNITS[key]
        s = to_si(f"noise.{key}", value, unit)
        if not (math.isfinite(s) and s >= 0):
            raise InputError(f"noise.{key}: {s:g} {unit} is out of range; allowed >= 0 {unit}")
        out[key] = s
    return out
