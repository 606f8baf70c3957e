"""Splits never let frames of one trial, group or time block land on two sides."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from tests.strategies import dataset_from_layout, make_dataset, trial_layouts

from slipkit.data import split_by_group, split_by_trial, split_time_blocks, time_blocks


def test_split_by_trial_partitions_the_trials() -> None:
    """Train, val and test are disjoint and together hold every trial once."""
    ds = make_dataset(n_trials=20, n_frames=5, with_events=False)
    split = split_by_trial(ds, test_size=0.2, val_size=0.25, seed=1)
    assert (12, 4, 4) == (len(split.train), len(split.val), len(split.test))
    assert sorted(ds.trial_ids) == sorted(split.train + split.val + split.test)


def test_split_by_trial_is_seeded() -> None:
    """The same seed gives the same split; another seed gives another."""
    ds = make_dataset(n_trials=20, n_frames=5, with_events=False)
    assert split_by_trial(ds, seed=3) == split_by_trial(ds, seed=3)
    assert split_by_trial(ds, seed=3) != split_by_trial(ds, seed=4)


def test_stratified_split_keeps_class_shares() -> None:
    """stratify='slip_class' puts both classes on both sides in equal shares."""
    ds = make_dataset(n_trials=20, n_frames=5, with_events=False)
    split = split_by_trial(ds, test_size=0.5, seed=0, stratify="slip_class")
    _, test_ds, _ = split.apply(ds)[0], split.apply(ds)[2], None
    assert {"linear": 5, "rotational": 5} == test_ds.trials[
        "slip_class"
    ].value_counts().to_dict()


def test_split_by_group_keeps_each_object_on_one_side() -> None:
    """No object appears in two of train, val and test."""
    ds = make_dataset(n_trials=24, n_frames=5, n_objects=6, with_events=False)
    train, val, test = split_by_group(
        ds, "object", test_size=0.34, val_size=0.25, seed=0
    ).apply(ds)
    sides = [set(d.trials["object"]) for d in (train, val, test)]
    assert all(sides)
    assert set() == (sides[0] & sides[1]) | (sides[0] & sides[2]) | (
        sides[1] & sides[2]
    )


def test_split_by_group_needs_two_groups() -> None:
    """A dataset with one object cannot be split by object; the error says so."""
    ds = make_dataset(n_trials=4, n_frames=5, n_objects=1, with_events=False)
    with pytest.raises(ValueError, match="only one value"):
        split_by_group(ds, "object")


def test_time_blocks_follow_the_block_length() -> None:
    """Blocks are contiguous block_s stretches within one trial (300 Hz, 1 s blocks)."""
    ds = dataset_from_layout([900, 450], ["a", "b"])
    blocks = time_blocks(ds, "force", block_s=1.0)
    assert [300, 300, 300, 300, 150] == np.bincount(blocks).tolist()


def test_time_block_split_matches_the_biotac_protocol() -> None:
    """30 s blocks, 20 % of blocks to test and 20 % of the rest to validation."""
    ds = dataset_from_layout(
        [300 * 300] * 5, list("abcde")
    )  # 5 trials x 300 s = 50 blocks
    split = split_time_blocks(ds, "force", block_s=30.0, seed=0)
    n_blocks = [
        len(np.unique(split.blocks[rows]))
        for rows in (split.train, split.val, split.test)
    ]
    assert [32, 8, 10] == n_blocks


@settings(max_examples=60, deadline=None)
@given(trial_layouts())
def test_no_block_or_trial_crosses_a_split(
    layout: tuple[list[int], list[str], float],
) -> None:
    """For any trial lengths and block length, every block (so every frame of it) and every
    trial-object group lies on exactly one side."""
    frames, objects, block_s = layout
    ds = dataset_from_layout(frames, objects)
    blocks = time_blocks(ds, "force", block_s)
    n_blocks = int(blocks.max()) + 1
    n_test = int(np.ceil(0.3 * n_blocks))
    if n_blocks - n_test - int(np.ceil(0.2 * (n_blocks - n_test))) < 1:
        with pytest.raises(ValueError, match="at least one on every side"):
            split_time_blocks(
                ds, "force", block_s=block_s, test_size=0.3, val_size=0.2, seed=0
            )
    else:
        split = split_time_blocks(
            ds, "force", block_s=block_s, test_size=0.3, val_size=0.2, seed=0
        )
        side = np.full(len(blocks), -1)
        for k, rows in enumerate((split.train, split.val, split.test)):
            assert (side[rows] == -1).all()
            side[rows] = k
        assert (side >= 0).all()
        for b in np.unique(blocks):
            assert 1 == len(np.unique(side[blocks == b]))
    # a block never spans two trials
    tid = ds.stream("force")["trial_id"].to_numpy()
    for b in np.unique(blocks):
        assert 1 == len(np.unique(tid[blocks == b]))
    if len(set(objects)) >= 2:
        train, _, test = split_by_group(ds, "object", test_size=0.5, seed=0).apply(ds)
        assert set() == set(train.trials["object"]) & set(test.trials["object"])
