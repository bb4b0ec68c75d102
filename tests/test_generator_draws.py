"""heli_env.generator_draws: many generators drawn in compiled code give numpy's numbers, bit for bit."""

import numpy as np
import pytest

from heli_env import generator_draws
from heli_env.generator_draws import Streams
from heli_env.vector_env import HeliAttitudeVectorEnv

N_UNIFORM, N_NORMAL = 30, 400


def _generators(seeds):
    return [np.random.Generator(np.random.PCG64(s)) for s in seeds]


def _numpy_draws(rng, n_traces, counts, key=True, trace_pin=-1, offset_pin=-1):
    """What the single env draws for an episode, in its order (heli_env.tasks.draw_episodes, line_phases,
    draw_noise_key)."""
    trace = int(rng.integers(n_traces))
    trace = trace if trace_pin < 0 else trace_pin
    offset = int(rng.integers(counts[trace]))
    uniforms = rng.random(N_UNIFORM)
    normals = rng.normal(0.0, 1.0, N_NORMAL)
    key_drawn = rng.integers(0, 2**64, dtype=np.uint64) if key else None
    return trace, (offset if offset_pin < 0 else offset_pin), uniforms, normals, key_drawn


@pytest.fixture(params=[True, False], ids=["compiled", "numpy"])
def compiled(request, monkeypatch):
    """Both ways of drawing: compiled (the default) and numpy's calls (where numba lacks numpy's tables)."""
    monkeypatch.setattr(generator_draws, "COMPILED", request.param)
    return request.param


@pytest.mark.parametrize("n_traces", [1, 5])
def test_every_draw_is_numpys_own_including_its_rare_branches(n_traces, compiled):
    """Copies' episodes drawn at once equal numpy's draws from the same seeds over three episodes each: the
    trace and offset (Lemire's bounded integers: a count of 1 draws nothing, 3e9 rejects about a third of its
    draws, 2**32 takes a 32-bit draw as it is), uniforms, normals (the ziggurat's wedges and tail) and the
    64-bit key; the 32-bit half a draw keeps carries over to the next episode as numpy's does."""
    seeds = range(1000, 1300)
    counts = np.array([1, 3_000_000_000, 2**32, 7, 12345], dtype=np.int64)[:max(n_traces, 1)]
    if n_traces == 1:
        counts = np.array([3_000_000_000], dtype=np.int64)
    streams, reference = Streams(len(seeds)), _generators(seeds)
    for i, rng in enumerate(_generators(seeds)):
        streams.adopt(i, rng)
    which = np.arange(len(seeds))
    slow = 0
    for _ in range(3):
        drawn = streams.draw(which, n_traces, counts, N_UNIFORM, N_NORMAL, True)
        for q, rng in enumerate(reference):
            expected = _numpy_draws(rng, n_traces, counts)
            assert drawn[0][q] == expected[0] and drawn[1][q] == expected[1], q
            np.testing.assert_array_equal(drawn[2][q], expected[2])
            np.testing.assert_array_equal(drawn[3][q], expected[3])
            assert drawn[4][q] == expected[4]
        slow += int(streams._mark_count.sum())
    minimal = 3 * len(seeds) * (N_UNIFORM + N_NORMAL + 1)  # one 64-bit draw each, the integers' halves aside
    assert slow > minimal + 100 or not compiled  # the ziggurat's slow paths and Lemire's rejections were taken


def test_pins_replace_what_was_drawn_as_the_single_env_does(compiled):
    """A pinned trace decides the offset's count; the pins replace the values, the draws still happen."""
    seeds = range(50, 80)
    counts = np.array([4, 9_000, 2_000_000_000], dtype=np.int64)
    streams, reference = Streams(len(seeds)), _generators(seeds)
    for i, rng in enumerate(_generators(seeds)):
        streams.adopt(i, rng)
    which = np.arange(len(seeds))[::-1].copy()  # any order of copies
    for pins in ((2, -1), (-1, 3), (1, 5)):
        traces, offsets, uniforms, normals, keys = streams.draw(which, 3, counts, N_UNIFORM, N_NORMAL, False, *pins)
        for q, i in enumerate(which):
            expected = _numpy_draws(reference[i], 3, counts, key=False, trace_pin=pins[0], offset_pin=pins[1])
            assert (traces[q], offsets[q]) == expected[:2]
            np.testing.assert_array_equal(normals[q], expected[3])
        assert keys.size == 0


def test_a_copy_put_back_draws_the_same_again_and_the_others_go_on(compiled):
    """put_back returns marked copies' generators (the 64-bit state and the kept 32-bit half) to the mark;
    copies not put back keep their place."""
    seeds = range(7, 27)
    counts = np.array([3_000_000_000], dtype=np.int64)  # one trace: an episode draws one 32-bit half
    streams = Streams(len(seeds))
    for i, rng in enumerate(_generators(seeds)):
        streams.adopt(i, rng)
    which = np.arange(len(seeds))
    streams.draw(which, 1, counts, N_UNIFORM, N_NORMAL, True)  # a half kept on some copies (rejections vary it)
    assert 0 < streams.kept[0].sum() < len(seeds) or not compiled
    streams.mark(which)
    first = streams.draw(which, 1, counts, N_UNIFORM, N_NORMAL, True)
    back = which[::2]
    streams.put_back(back)
    again = streams.draw(back, 1, counts, N_UNIFORM, N_NORMAL, True)
    for got, was in zip(again, first):
        np.testing.assert_array_equal(got, was[::2])
    on = streams.draw(which[1::2], 1, counts, N_UNIFORM, N_NORMAL, True)  # the others: their third episode
    for q, i in enumerate(which[1::2]):
        rng = _generators([seeds[i]])[0]
        for _ in range(2):
            _numpy_draws(rng, 1, counts)
        expected = _numpy_draws(rng, 1, counts)
        assert on[1][q] == expected[1]
        np.testing.assert_array_equal(on[3][q], expected[3])


def test_a_generator_other_than_pcg64_is_refused_by_name():
    with pytest.raises(TypeError, match="PCG64.*got MT19937"):
        Streams(1).adopt(0, np.random.Generator(np.random.MT19937(1)))


def test_a_vector_env_drawing_through_numpy_runs_the_compiled_envs_episodes(monkeypatch):
    """The fallback is the same env: episodes, autoresets drawn ahead, and a reset with options that puts a draw
    ahead back, observed alike."""
    def run():
        venv = HeliAttitudeVectorEnv(4, episode_seconds=0.1)
        observed = [venv.reset(seed=3)[0]]
        for step in range(40):
            if step == 17:
                observed.append(venv.reset(options={"trace": 1, "reset_mask": np.array([0, 1, 0, 1], bool)})[0])
            observed.append(venv.step(np.full((4, 3), 0.1))[0])
        return observed

    compiled = run()
    monkeypatch.setattr(generator_draws, "COMPILED", False)
    for got, expected in zip(run(), compiled):
        assert np.array_equal(got, expected)


def test_counts_beyond_a_32_bit_draw_are_refused_not_drawn_wrong():
    streams = Streams(1)
    streams.adopt(0, np.random.Generator(np.random.PCG64(0)))
    with pytest.raises(ValueError, match="1 to 2\\*\\*32 traces and windows"):
        streams.draw(np.arange(1), 1, np.array([2**32 + 1], dtype=np.int64), 2, 0, False)
