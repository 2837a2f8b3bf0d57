"""The rollout's batch: every distinct actor input stored once (``Inputs``, ``distinct_rows``)."""
import numpy as np
import pytest
import torch

from oapo_lite.neural import rollout
from oapo_lite.neural.rollout import Inputs, States, distinct_rows


def unique_by_bytes(*columns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The reference: np.unique over every row's bytes, the columns side by side."""
    raw = np.ascontiguousarray(np.concatenate([np.ascontiguousarray(c).view(np.uint8) for c in columns], 1))
    _, first, inverse = np.unique(raw.view(np.dtype((np.void, raw.shape[1]))).ravel(), return_index=True,
                                  return_inverse=True)
    return first, inverse


def repeating_rows(rng: np.random.Generator, rows: int, width: int) -> np.ndarray:
    """float32 rows drawn from a small table, some with -0.0 or NaN: equal as numbers, not as bytes, or the reverse."""
    table = rng.standard_normal((max(1, rows // 50), width)).astype(np.float32)
    table[::3, 0] = 0.0
    table[1::3, 0] = -0.0
    table[2::5, -1] = np.nan
    return table[rng.integers(0, len(table), rows)]


@pytest.mark.parametrize("one_hash", [False, True], ids=["hashed", "every row one hash"])
def test_distinct_rows_are_np_unique_over_the_rows_bytes(monkeypatch, one_hash):
    if one_hash:  # rows that share a hash without being equal: np.unique must decide
        monkeypatch.setattr(rollout, "_row_hash", lambda raw: np.zeros(len(raw[0]), np.uint64))
    rng = np.random.default_rng(0)
    for rows, width in ((1, 1), (7, 3), (3200, 72), (1600, 163)):
        obs = repeating_rows(rng, rows, width)
        avail = rng.random((rows, 5)) < 0.9
        for columns in ((obs,), (obs, avail)):
            first, inverse = distinct_rows(*columns)
            want_first, want_inverse = unique_by_bytes(*columns)
            np.testing.assert_array_equal(first, want_first)
            np.testing.assert_array_equal(inverse, want_inverse)


def test_inputs_store_each_distinct_input_once_and_give_back_every_sample():
    rng = np.random.default_rng(1)
    n, B = 2, 400
    obs = repeating_rows(rng, n * B, 6).reshape(n, B, 6)
    avail = (rng.random((n, B, 4)) < 0.7)
    inputs = Inputs.of(obs, avail)
    assert torch.equal(inputs.obs[inputs.index].view(torch.int32), torch.from_numpy(obs).view(torch.int32))
    assert torch.equal(inputs.avail[inputs.index], torch.from_numpy(avail))
    rows = np.concatenate([inputs.obs.numpy().view(np.uint8), inputs.avail.numpy().view(np.uint8)], 1)
    assert len(np.unique(rows, axis=0)) == len(rows)


def test_states_store_each_distinct_state_once_and_give_back_every_step():
    rng = np.random.default_rng(2)
    T, N = 50, 32
    state = torch.from_numpy(repeating_rows(rng, (T + 1) * N, 163).reshape(T + 1, N, 163))
    states = States.of(state)
    assert torch.equal(states.rows[states.index].view(torch.int32), state.view(torch.int32))
    assert len(np.unique(states.rows.numpy().view(np.uint8), axis=0)) == len(states.rows) < (T + 1) * N


def test_the_row_hash_of_a_row_is_the_same_wherever_it_sits():
    """Exact by construction: a row alone, and the same row at every place of a batch of other
    rows, hashes alike (a floating-point product could round it by its place in the batch); rows
    that differ in their bytes hash apart."""
    rng = np.random.default_rng(3)
    as_bytes = lambda *columns: [np.ascontiguousarray(c).view(np.uint8) for c in columns]
    for width in (1, 3, 75, 163):
        batch = repeating_rows(rng, 3000, width)
        masks = rng.random((3000, 5)) < 0.5
        row, mask = batch[:1], masks[:1]
        batch[::7], masks[::7] = row, mask
        hashes = rollout._row_hash(as_bytes(batch, masks))
        np.testing.assert_array_equal(hashes[::7], np.repeat(rollout._row_hash(as_bytes(row, mask)), len(batch[::7])))
        assert len(np.unique(hashes)) == len(unique_by_bytes(batch, masks)[0])
    assert rollout._row_hash(as_bytes(np.zeros((0, 4), np.float32))).shape == (0,)
