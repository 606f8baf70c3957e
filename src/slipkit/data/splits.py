"""Train / validation / test splits that never let one trial, group or time block
straddle two sides.

Built on scikit-learn's ``train_test_split`` and ``GroupShuffleSplit`` so the
shuffling and proportions are the well-tested ones; this module only decides
what the unit of splitting is.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from sklearn.model_selection import GroupShuffleSplit, train_test_split

from slipkit.data.dataset import Dataset
from slipkit.errors import SlipkitError


class SplitError(SlipkitError, ValueError):
    """A split that cannot be made (too few trials, groups or blocks for its sides).

    A ``ValueError`` too, so callers that catch that keep working.
    """


@dataclass(frozen=True)
class TrialSplit:
    """Trial ids on each side of a split (``val`` may be empty)."""

    train: tuple[str, ...]
    val: tuple[str, ...]
    test: tuple[str, ...]

    def apply(self, dataset: Dataset) -> tuple[Dataset, Dataset, Dataset]:
        """The three sub-datasets (train, val, test)."""
        return (
            dataset.subset(self.train, name=f"{dataset.name}:train"),
            dataset.subset(self.val, name=f"{dataset.name}:val"),
            dataset.subset(self.test, name=f"{dataset.name}:test"),
        )


@dataclass(frozen=True)
class BlockSplit:
    """Row indices of one stream's long table on each side, and each row's block id.

    Attributes
    ----------
    stream : str
        The stream whose rows are split.
    blocks : ndarray of int
        Block id of every row (a block never crosses trials).
    train, val, test : ndarray of int
        Row positions (``iloc``) in the stream's long table.
    """

    stream: str
    blocks: np.ndarray
    train: np.ndarray
    val: np.ndarray
    test: np.ndarray


def _check_fraction(name: str, value: float) -> None:
    number = isinstance(value, int | float) and not isinstance(value, bool)
    if not number or not 0.0 <= value < 1.0:
        raise SplitError(f"{name} must be a number in [0, 1); got {value!r}")


def _check_enough(n: int, unit: str, test_size: float, val_size: float) -> None:
    """Refuse, with a clear message, a split that would leave a side empty.

    Counts follow scikit-learn's rule (test and val sizes rounded up).
    """
    n_test = int(np.ceil(test_size * n))
    n_val = int(np.ceil(val_size * (n - n_test)))
    if n - n_test - n_val < 1 or (test_size and n_test < 1):
        raise SplitError(
            f"cannot split {n} {unit} into test {test_size:.0%} and val {val_size:.0%} "
            "with at least one on every side; use fewer or smaller sides, or more data"
        )


def split_by_trial(
    dataset: Dataset,
    *,
    test_size: float = 0.2,
    val_size: float = 0.0,
    seed: int = 0,
    stratify: str | None = None,
) -> TrialSplit:
    """Split whole trials; ``val_size`` is a fraction of the training trials.

    ``test_size=0.5`` is the TacTip paper's "train on half of the runs".
    ``stratify`` names a trial label (e.g. ``slip_class``) to keep class shares equal.
    """
    _check_fraction("test_size", test_size)
    _check_fraction("val_size", val_size)
    ids = np.asarray(dataset.trial_ids, dtype=object)
    strat = (
        None if stratify is None else dataset.trials[stratify].astype(str).to_numpy()
    )
    _check_enough(len(ids), "trials", test_size, val_size)
    pos = np.arange(len(ids))
    tr, te = pos, pos[:0]
    if test_size:
        tr, te = train_test_split(
            pos, test_size=test_size, random_state=seed, stratify=strat
        )
    va = tr[:0]
    if val_size:
        tr, va = train_test_split(
            tr,
            test_size=val_size,
            random_state=seed + 1,
            stratify=None if strat is None else strat[tr],
        )
    return TrialSplit(
        tuple(map(str, ids[tr])), tuple(map(str, ids[va])), tuple(map(str, ids[te]))
    )


def split_by_group(
    dataset: Dataset,
    group: str = "object",
    *,
    test_size: float = 0.2,
    val_size: float = 0.0,
    seed: int = 0,
) -> TrialSplit:
    """Split so that every value of ``group`` (e.g. an object) lies on one side only.

    The fractions count groups, not trials (``GroupShuffleSplit``).
    """
    _check_fraction("test_size", test_size)
    _check_fraction("val_size", val_size)
    if group not in dataset.trials.columns:
        raise KeyError(
            f"no column {group!r} in the trials table; columns: {list(dataset.trials.columns)}"
        )
    ids = np.asarray(dataset.trial_ids, dtype=object)
    groups = dataset.trials[group].astype(str).to_numpy()
    if len(set(groups)) < 2:
        raise SplitError(
            f"cannot split by {group!r}: only one value ({groups[0]!r}) in the dataset"
            if len(groups)
            else f"cannot split by {group!r}: the dataset holds no trials"
        )
    _check_enough(len(set(groups)), f"values of {group!r}", test_size, val_size)
    tr, te = next(
        GroupShuffleSplit(n_splits=1, test_size=test_size, random_state=seed).split(
            ids, groups=groups
        )
    )
    val_idx = tr[:0]
    if val_size:
        sub, v = next(
            GroupShuffleSplit(
                n_splits=1, test_size=val_size, random_state=seed + 1
            ).split(tr, groups=groups[tr])
        )
        tr, val_idx = tr[sub], tr[v]
    return TrialSplit(
        tuple(map(str, ids[tr])),
        tuple(map(str, ids[val_idx])),
        tuple(map(str, ids[te])),
    )


def time_blocks(dataset: Dataset, stream: str, block_s: float) -> np.ndarray:
    """Block id of every row of ``stream``: contiguous ``block_s``-second stretches of one trial."""
    if not block_s > 0:
        raise SplitError(f"block_s must be > 0 s; got {block_s}")
    table = dataset.stream(stream)
    tid = table["trial_id"].to_numpy()
    t = table["t"].to_numpy(dtype=np.float64)
    trial_code = np.unique(tid, return_inverse=True)[1]
    t0 = (
        table.groupby("trial_id", sort=False)["t"]
        .transform("min")
        .to_numpy(dtype=np.float64)
    )
    within = np.floor((t - t0) / block_s).astype(np.int64)
    pairs = np.stack([trial_code, within], axis=1)
    return np.unique(pairs, axis=0, return_inverse=True)[1].reshape(-1)


def split_time_blocks(
    dataset: Dataset,
    stream: str,
    *,
    block_s: float = 30.0,
    test_size: float = 0.2,
    val_size: float = 0.2,
    seed: int = 0,
) -> BlockSplit:
    """The BioTac paper's split: cut recordings into ``block_s`` intervals, shuffle
    the intervals, 80 % train / 20 % test, and 20 % of train for validation.

    Frames of one interval never cross sides.
    """
    _check_fraction("test_size", test_size)
    _check_fraction("val_size", val_size)
    blocks = time_blocks(dataset, stream, block_s)
    rows = np.arange(len(blocks))
    n_blocks = int(blocks.max()) + 1 if len(blocks) else 0
    _check_enough(
        n_blocks, f"blocks of {block_s} s in stream {stream!r}", test_size, val_size
    )
    tr, te = next(
        GroupShuffleSplit(n_splits=1, test_size=test_size, random_state=seed).split(
            rows, groups=blocks
        )
    )
    va = tr[:0]
    if val_size:
        sub, v = next(
            GroupShuffleSplit(
                n_splits=1, test_size=val_size, random_state=seed + 1
            ).split(tr, groups=blocks[tr])
        )
        tr, va = tr[sub], tr[v]
    return BlockSplit(stream, blocks, np.sort(tr), np.sort(va), np.sort(te))
