"""Typed values passed between the fleet modules: the settings of a run and one loop's result."""
from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from dataclasses import dataclass, field
from typing import Any

__all__ = ["FleetSettings", "LoopResult", "TABLE_COLUMNS", "RESULT_VERSION", "loop_key"]

#: Version of the per-loop result; a change makes every stored result stale (recomputed on resume).
#: 2: a recorded valve position (``mv``) sends a loop to the full diagnosis and decides its verdict.
#: 3: a wide export's tags read status texts as missing samples, refuse duplicated columns and time stamps
#: that go back, and ``--columns mode=`` switches the mode column off (it was read regardless).
#: 4: the OP's range and the time stamps' format read from the data, the process model chosen from the data
#: where no tag says it, and the cause of an oscillation (``cause``, ``p_*``, ``cause_evidence``).
RESULT_VERSION = 4

#: Columns of ``loops.parquet`` / ``loops.csv``, in order (the first eleven are the issue's minimum).
TABLE_COLUMNS = ("loop", "status", "message", "stiction", "S", "J", "effects", "rmse_base", "rmse_final",
                 "oscillation", "seconds", "cpu_seconds", "p_stiction", "weight", "score", "action", "stage",
                 "oscillating", "regularity", "period_s", "amplitude_op", "horch", "horch_index", "n", "dt", "gaps",
                 "source", "tag", "key", "cause", "p_valve", "p_tuning", "p_disturbance", "p_sensor", "p_saturation",
                 "suggested_kc", "cause_evidence", "cause_scores")


@dataclass(frozen=True)
class FleetSettings:
    """Settings of a fleet run (all but ``report_dir`` enter the resume hash).

    Attributes
    ----------
    plant, actuator : str, process model and actuator of :func:`valve_gym.diagnosis.diagnose`
        (``plant='auto'``: each loop's from its tag, :func:`valve_gym.diagnosis.plant_choice.plant_from_name`)
    candidates : tuple of str, candidate effects of the full diagnosis
    holdout : float, fraction held out of the selection fits
    effort : str, search budget of the full diagnosis
    search : str, ``'full'`` or ``'fast'`` (the opt-in fast search of :func:`valve_gym.diagnosis.diagnose`)
    op_lag : 0, 1 or 'auto' (default), how the recorder pairs OP and PV (``op_lag`` of
        :func:`valve_gym.diagnosis.diagnose`)
    seed : int, seed of the full diagnosis
    full : bool, run the full diagnosis on every loop (default: only on oscillating loops)
    columns : tuple of (role, column) pairs, optional, for one-recording CSV files (of a wide export's
        tags only ``('mode', None)`` and ``('sp', None)`` are used: those columns are not read)
    op_range : (lo, hi), optional, raw controller-output range mapped to 0..1
    mv_range : (lo, hi), optional, raw valve-position range mapped to 0..1 (default: ``op_range``)
    max_gap : int, longest stretch without samples bridged, in scans
    dayfirst : bool or None, dates ``D/M/Y`` (True) or ``M/D/Y`` (False); None reads it from the data
    time_unit : str or None, unit of a numeric time column (``'s'``, ``'ms'``, ``'us'``, ``'days'``); None
        reads it from the data
    dt : float or None, sample time [s] of one-recording files without a time column (``--dt``)
    gaps : str, ``'longest'`` (default: keep each loop's longest stretch without a gap longer than
        ``max_gap``) or ``'error'`` (such a loop fails, naming the gap)
    report_dir : str, optional, folder for a full report per fully diagnosed loop
    """

    plant: str = "auto"
    actuator: str = "valve"
    candidates: tuple[str, ...] = ()
    holdout: float = 0.3
    effort: str = "auto"
    search: str = "full"
    op_lag: int | str = "auto"
    seed: int = 0
    full: bool = False
    columns: tuple[tuple[str, Any], ...] | None = None
    op_range: tuple[float, float] | None = None
    max_gap: int = 5
    mv_range: tuple[float, float] | None = None
    dayfirst: bool | None = None
    time_unit: str | None = None
    dt: float | None = None
    gaps: str = "longest"
    report_dir: str | None = field(default=None, compare=False)

    def load_kw(self) -> dict[str, Any]:
        """The keywords of :func:`~valve_gym.fleet.sources.load_loop` that these settings give."""
        return {"columns": dict(self.columns) if self.columns else None, "op_range": self.op_range,
                "max_gap": self.max_gap, "mv_range": self.mv_range, "dayfirst": self.dayfirst,
                "time_unit": self.time_unit, "dt": self.dt, "gaps": self.gaps}

    def hash_text(self) -> str:
        """Canonical JSON of the settings that change a result."""
        d = dataclasses.asdict(self)
        d.pop("report_dir")
        if d["search"] == "full":           # the default: keys of runs made before it existed stay valid
            d.pop("search")
        if d["op_lag"] == 0:                # the default before auto: those runs keep their keys
            d.pop("op_lag")
        for k in ("mv_range", "dayfirst", "time_unit", "dt"):     # the defaults: read from the data
            if d[k] is None:
                d.pop(k)
        if d["gaps"] == "longest":          # the default: keys of runs made before it existed stay valid
            d.pop("gaps")
        d["version"] = RESULT_VERSION
        return json.dumps(d, sort_keys=True, default=list)


def loop_key(fingerprint: str, kind: str, tag: str, settings: FleetSettings) -> str:
    """Resume key of a loop: SHA-256 of its file's content, its tag and the settings (20 hex digits)."""
    text = "|".join((fingerprint, kind, tag, settings.hash_text()))
    return hashlib.sha256(text.encode()).hexdigest()[:20]


def _jsonable(v):
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, tuple):
        return list(v)
    return v


@dataclass(frozen=True)
class LoopResult:
    """What the fleet found on one loop (one row of ``loops.parquet``).

    Attributes
    ----------
    loop : str, loop name
    status : str, ``'ok'``, ``'failed'`` (the data cannot be used; ``message`` says why and what to do)
        or ``'error'`` (an internal error or a lost worker; retried on resume)
    message : str, one line: the evidence, or why it failed
    stiction : str, model-based verdict: ``'yes'``, ``'no'``, ``'undecided'``, or ``'not tested'``
        (screening only, or a pump)
    S, J : float, stick band and slip jump [fraction of stroke]; NaN when the diagnosis does not give them
    effects : str, effects the diagnosis added, ``;``-separated, most important first; ``'none'``
    rmse_base, rmse_final : float, free-run RMSE of the base and final models [PV units]; NaN if screened only
    oscillation : float, amplitude of the control error's oscillation [PV units]; 0 when none
    seconds : float, wall time of this loop [s]
    cpu_seconds : float, CPU time of this loop in its worker [s] (``time.process_time``)
    p_stiction : float, calibrated stiction probability from the diagnosis (NaN when it reports none)
    weight : float, stiction evidence weight 0..1 used in the ranking (see :mod:`.actions`)
    score : float, ranking score [% of stroke] (see :mod:`.actions`)
    action : str, recommended action
    stage : str, ``'screen'`` or ``'full'`` (full diagnosis run)
    oscillating : bool
    regularity : float, Thornhill's ``r`` (NaN when undefined)
    period_s : float, oscillation period [s] (NaN when undefined)
    amplitude_op : float, controller-output amplitude at that period [fraction of stroke]
    horch : str, Horch's verdict; horch_index : float, his phase index 0..1 (NaN when none)
    n : int, samples used; dt : float, scan [s]
    gaps : int, gaps found while resampling
    notes : tuple of str, repairs and resampling done
    source : str, file; tag : str, tag of a wide export
    key : str, resume key (content + settings hash)
    cause : str, most probable cause of the oscillation (``'stiction'``, ``'tuning'``, ``'disturbance'``,
        ``'sensor'``, ``'saturation'``; ``'none'`` when it does not oscillate; ``''`` when not diagnosed),
        :mod:`valve_gym.diagnosis.causes`
    p_valve, p_tuning, p_disturbance, p_sensor, p_saturation : float, probability of each cause (NaN without one)
    suggested_kc : float, controller gain for a gain margin of 2 [OP units per PV unit] (NaN unless tuning)
    cause_evidence : str, the cause and its evidence in words
    cause_scores : str, the causes' log-odds scores as JSON (for the fleet's shared-period evidence)
    """

    loop: str
    status: str
    message: str
    stiction: str = "not tested"
    S: float = math.nan
    J: float = math.nan
    effects: str = ""
    rmse_base: float = math.nan
    rmse_final: float = math.nan
    oscillation: float = math.nan
    seconds: float = 0.0
    cpu_seconds: float = math.nan
    p_stiction: float = math.nan
    weight: float = math.nan
    score: float = math.nan
    action: str = ""
    stage: str = ""
    oscillating: bool = False
    regularity: float = math.nan
    period_s: float = math.nan
    amplitude_op: float = math.nan
    horch: str = ""
    horch_index: float = math.nan
    n: int = 0
    dt: float = math.nan
    gaps: int = 0
    notes: tuple[str, ...] = ()
    source: str = ""
    tag: str = ""
    key: str = ""
    cause: str = ""
    p_valve: float = math.nan
    p_tuning: float = math.nan
    p_disturbance: float = math.nan
    p_sensor: float = math.nan
    p_saturation: float = math.nan
    suggested_kc: float = math.nan
    cause_evidence: str = ""
    cause_scores: str = ""

    def to_dict(self) -> dict:
        """JSON-ready dict (NaN -> None, tuples -> lists)."""
        return {f.name: _jsonable(getattr(self, f.name)) for f in dataclasses.fields(self)}

    @classmethod
    def from_dict(cls, d: dict) -> LoopResult:
        """Inverse of :meth:`to_dict` (None -> NaN for the float fields); unknown keys are ignored."""
        kw = {}
        for f in dataclasses.fields(cls):
            if f.name not in d:
                continue
            v = d[f.name]
            if f.type in ("float",):
                v = math.nan if v is None else float(v)
            elif f.name == "notes":
                v = tuple(v or ())
            kw[f.name] = v
        return cls(**kw)

    def row(self) -> dict:
        """The table row: :data:`TABLE_COLUMNS` only."""
        return {c: getattr(self, c) for c in TABLE_COLUMNS}
