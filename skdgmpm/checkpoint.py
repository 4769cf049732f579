"""Checkpoints: all a run needs to go on, bit for bit, from where it stopped.

``checkpoint.npz`` in the output folder holds

- the state: every field of `ParticleState` (t, step, U, Q, x, the wave speeds that set the next
  time step, the grid dofs of DGFEM, the health record, the laws' internal variables ``history``);
- the steppers' own run state, which a step reads or accumulates (`RUN_STATE`): the boundary work
  ``external_work``, ``dt_growth`` and ``dt_recent`` (every stepper), ``picard`` (ADER: predictor iteration counts) and
  ``limited_cells`` (DGFEM: the limiter's count). Everything else a stepper sets while stepping
  is a cache rebuilt from the state at the start of each step (DGMPM ``_kept``, DGFEM and ADER
  ``history_n``, ADER ``_repeated``, MPM ``_last_shape``: arrays the next step overwrites; DGMPM
  ``_split``: set-up from the grid, built when first needed);
  tests/test_checkpoint.py checks that a step changes nothing
  else;
- the scene as run (overrides applied) with its path (mesh files resolve against it), the run's
  options (frames), the energy history, the probes' rows, the frames written so far and the next
  frame's index, the wall and start-up times so far.

It is written atomically (`outdir.atomic_write`): a run killed while writing it keeps the previous
one. ``run.checkpoint_every`` sets how often: an integer is a number of steps, a string "30 s",
"10 min" or "2 h" a wall-clock interval; default "10 min". A run also writes one when stopped by
SIGINT or SIGTERM, and removes it when it ends ("ok"): there is nothing left to resume.
"""
import json
import re
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from .errors import InputError
from .outdir import atomic_write

NAME = "checkpoint.npz"
FORMAT = 2                      # 1: the CFL guard kept the last speed-up only (dt_trend = 1 / speed-up)
RUN_STATE = ("external_work", "dt_growth", "dt_recent", "limited_cells", "picard")
DEFAULT_EVERY = "10 min"
_UNITS = {"s": 1.0, "min": 60.0, "h": 3600.0}


def parse_every(scene):
    """``run.checkpoint_every`` -> ("steps", n) or ("seconds", s)."""
    value = scene.get("run.checkpoint_every", DEFAULT_EVERY)
    where = scene.where("run.checkpoint_every")
    if isinstance(value, int) and not isinstance(value, bool):
        if value < 1:
            raise InputError(f"{where} = {value!r} must be a number of steps >= 1 or a time such as '10 min'")
        return "steps", value
    m = re.fullmatch(r"\s*([0-9.eE+-]+)\s*(s|min|h)\s*", value) if isinstance(value, str) else None
    try:
        seconds = float(m[1]) * _UNITS[m[2]] if m else None
    except ValueError:
        seconds = None
    if seconds is None or not 0 < seconds < np.inf:
        raise InputError(f"{where} = {value!r} must be a number of steps >= 1 or a time such as "
                         "'30 s', '10 min', '2 h'")
    return "seconds", seconds


class Schedule:
    """When the next periodic checkpoint is due."""

    def __init__(self, every, step):
        self.kind, self.amount = every
        self.last_step, self.last_time = step, time.monotonic()

    def due(self, step):
        if self.kind == "steps":
            return step - self.last_step >= self.amount
        return time.monotonic() - self.last_time >= self.amount

    def done(self, step):
        self.last_step, self.last_time = step, time.monotonic()


def stepper_state(stepper):
    """{name: value} of the stepper's accumulated run state (`RUN_STATE`), JSON-ready."""
    out = {}
    for name in RUN_STATE:
        value = getattr(stepper, name, None)
        if value is None:
            continue
        out[name] = asdict(value) if hasattr(value, "__dataclass_fields__") else value
    return out


def restore_stepper(stepper, saved):
    for name, value in saved.items():
        current = getattr(stepper, name)
        if hasattr(current, "__dataclass_fields__"):
            setattr(stepper, name, type(current)(**value))
        else:
            setattr(stepper, name, type(current)(value))


@dataclass
class Checkpoint:
    """What `read` returns: the scene data, state, stepper state and the run's bookkeeping."""

    scene_name: str
    scene_data: dict
    scene_path: str
    state: object                 # ParticleState
    stepper: dict
    history: dict                 # {column: list}
    entries: list                 # [(t, file name, step)]
    next_frame: int
    n_frames: int
    wall_s: float
    startup_s: float
    dt0: float
    scene_overridden: tuple = ()  # the keys --set gave (messages, and the ignored-key warnings)
    probes: np.ndarray = None     # (rows, columns) of the probes (`skdgmpm.probes.Probes.table`)


def write(folder, scene, state, stepper, history, entries, next_frame, n_frames, wall_s, startup_s, dt0,
          probes=None):
    """Write ``folder/checkpoint.npz`` atomically."""
    arrays = {"U": state.U, "Q": state.Q, "x": state.x}
    for name in ("speed", "dofs", "history"):
        value = getattr(state, name)
        if value is not None:
            arrays[name] = value
    for key, values in history.items():
        arrays[f"energy_{key}"] = np.asarray(values)
    if probes is not None:
        arrays["probes"] = probes.table()
    meta = {
        "format": FORMAT, "t": state.t, "step": int(state.step), "health": state.health,
        # the next step's fastest wave: a state made by a law pass holds no speeds
        "fastest": None if state.fastest is None else float(state.fastest),
        "scene": {"name": scene.name, "data": scene.data, "path": str(Path(scene.path).resolve()) if scene.path else None,
                  "overridden": list(scene.overridden)},
        "stepper": stepper_state(stepper), "history_keys": list(history),
        "entries": [[float(t), name, int(step)] for t, name, step in entries], "next_frame": int(next_frame),
        "n_frames": int(n_frames), "wall_s": float(wall_s), "startup_s": float(startup_s),
        "dt0": None if dt0 is None else float(dt0),
    }
    arrays["meta"] = np.array(json.dumps(meta))

    def save(tmp):
        with open(tmp, "wb") as fh:
            np.savez(fh, **arrays)

    atomic_write(Path(folder) / NAME, save)


def read(folder):
    """The `Checkpoint` in ``folder``; InputError (one line) when there is none or it is unreadable."""
    from .scheme import ParticleState

    path = Path(folder) / NAME
    if not Path(folder).is_dir():
        raise InputError(f"--resume {folder}: no such directory")
    if not path.is_file():
        raise InputError(f"--resume {folder}: no {NAME} there (the run finished, or stopped before its "
                         "first checkpoint)")
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
        meta = json.loads(str(arrays.pop("meta")))
    except (OSError, ValueError, KeyError) as exc:
        raise InputError(f"--resume {folder}: {NAME} is unreadable ({exc})") from None
    if meta.get("format") == 1 and "dt_trend" in meta["stepper"]:      # the guard's window starts afresh
        trend = meta["stepper"].pop("dt_trend")
        meta["stepper"]["dt_growth"] = [1.0 / trend if trend > 0 else 1.0]
        meta["format"] = FORMAT
    if meta.get("format") != FORMAT:
        raise InputError(f"--resume {folder}: {NAME} has format {meta.get('format')!r}, this version reads {FORMAT}")
    state = ParticleState(meta["t"], arrays["U"], arrays["Q"], arrays["x"], meta["step"], arrays.get("speed"),
                          arrays.get("dofs"), meta["health"], arrays.get("history"), meta.get("fastest"))
    history = {k: list(arrays[f"energy_{k}"]) for k in meta["history_keys"]}
    s = meta["scene"]
    return Checkpoint(s["name"], s["data"], s["path"], state, meta["stepper"], history,
                      [(t, name, step) for t, name, step in meta["entries"]], meta["next_frame"],
                      meta["n_frames"], meta["wall_s"], meta["startup_s"], meta["dt0"],
                      tuple(s.get("overridden", ())), arrays.get("probes"))
