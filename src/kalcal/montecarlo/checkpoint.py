"""Checkpoints of a Monte Carlo run: the merged sums of the blocks finished so far.

Blocks merge in block order, so a checkpoint holds the sums of blocks 0 .. b-1 and the index b: a
resumed run continues from block b and ends with exactly the sums of an uninterrupted one. The file is
written to a temporary name and renamed, so a run killed while writing leaves the previous checkpoint
whole. A fingerprint of the run's settings (scenario, N, seed, engine, block size) is stored with it,
and a checkpoint written for other settings is refused.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
from pathlib import Path

import numpy as np

from kalcal.errors import ConfigError
from kalcal.montecarlo.accumulators import MomentSums

_NONE = "__none__"


def _exact(value):
    """numpy arrays and scalars as exact JSON (lists of round-trip floats), not their abbreviated text."""
    return value.tolist() if hasattr(value, "tolist") else str(value)


def fingerprint(settings: dict) -> str:
    """A stable digest of a run's settings (any JSON-serializable mapping; numpy values exactly)."""
    text = json.dumps(settings, sort_keys=True, default=_exact)
    return hashlib.sha256(text.encode()).hexdigest()


def save(path: str | Path, sums: MomentSums, next_block: int, digest: str) -> None:
    """Write the sums of blocks [0, next_block) atomically."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    arrays = {}
    for field in dataclasses.fields(sums):
        if field.name == "effect_blocks":
            continue
        value = getattr(sums, field.name)
        arrays[field.name] = np.array(_NONE) if value is None else np.asarray(value)
    if sums.effect_blocks is not None:  # the groups as three stacked arrays (no pickles in a checkpoint)
        counts, effects, mses = zip(*sums.effect_blocks)
        arrays["effect_blocks_count"] = np.asarray(counts, dtype=np.int64)
        arrays["effect_blocks_effect"] = np.stack(effects)
        arrays["effect_blocks_mse"] = np.stack(mses)
    temporary = path.with_name(path.name + ".tmp")
    with temporary.open("wb") as handle:
        np.savez(handle, next_block=next_block, fingerprint=digest, **arrays)
        handle.flush()
        os.fsync(handle.fileno())
    os.replace(temporary, path)


def load(path: str | Path, digest: str) -> tuple[MomentSums, int] | None:
    """The sums and next block of an existing checkpoint, None when there is none.

    Raises ConfigError when the checkpoint belongs to a run with other settings or cannot be read.
    """
    path = Path(path)
    if not path.exists():
        return None
    try:
        with np.load(path, allow_pickle=False) as data:
            stored = str(data["fingerprint"])
            next_block = int(data["next_block"])
            values = {}
            for field in dataclasses.fields(MomentSums):
                if field.name == "effect_blocks":
                    continue
                value = data[field.name]
                values[field.name] = None if value.dtype.kind == "U" and str(value) == _NONE else value
            # a checkpoint written without the groups resumes without them: the bound's own Monte Carlo
            # error is then reported as not available
            if "effect_blocks_count" in data.files:
                values["effect_blocks"] = tuple(
                    (int(c), e, m)
                    for c, e, m in zip(data["effect_blocks_count"], data["effect_blocks_effect"], data["effect_blocks_mse"])
                )
    except (OSError, ValueError, KeyError) as exc:
        raise ConfigError(f"--checkpoint {path}: not a kalcal checkpoint ({exc})") from None
    if stored != digest:
        raise ConfigError(
            f"--checkpoint {path}: written by a run with other settings (scenario, -n, --seed, --engine); "
            "use another file or delete it"
        )
    values["count"] = int(values["count"])
    return MomentSums(**values), next_block
