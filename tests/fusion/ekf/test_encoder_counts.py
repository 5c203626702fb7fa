"""EncoderCounts: the raw counts a filter holds between frames; EKFOptions: its options."""

import dataclasses

import numpy as np
import pytest

from fusion.ekf.ekf_options import EKFOptions
from fusion.ekf.encoder_counts import EncoderCounts
from fusion.ekf.model_ekf import ModelEKF
from fusion.exceptions import FilterOptionError
from lti_motion.recordings.ticks import tick_deltas


@pytest.mark.parametrize("bits", [8, 16, 24, 64])
def test_each_frame_step_and_the_span_are_tick_deltas_on_the_ring(rng, bits):
    """Frame by frame, the step is tick_deltas of consecutive counts and the span that of
    the reference and the last frame, across the wrap, for any counter width."""
    modulus = 1 << min(bits, 62)
    half = modulus // 2
    raw = (np.cumsum(rng.integers(-half // 4, half // 4, size=(60, 2)), axis=0)
           + modulus - 7)
    raw = raw % modulus if bits < 63 else raw
    counts = EncoderCounts(counter_bits=bits, initial_ticks=tuple(raw[0]))
    steps = tick_deltas(raw, axis=0, counter_bits=bits)
    for k in range(1, len(raw)):
        counts.observe(int(raw[k, 0]), int(raw[k, 1]))
        counts.advance()
        assert counts.step == tuple(steps[k - 1]), k
        assert counts.span() == tuple(tick_deltas(raw[[0, k]], axis=0,
                                                  counter_bits=bits)[0]), k
    np.testing.assert_array_equal(counts.pair(), raw[[0, -1]])
    assert counts.accumulating and counts.periods == len(raw) - 1
    counts.rebase()
    assert counts.reference == counts.frame and counts.periods == 0
    assert not counts.accumulating and counts.span() == (0, 0)


def test_the_jump_compares_a_frame_step_with_the_one_before():
    """|d_k| against |d_(k-1)|: no jump until two steps are known, the larger wheel's
    change after."""
    counts = EncoderCounts()
    assert counts.observe(100, 200) == 0.0 and counts.step is None       # nothing before
    assert counts.reference is None and not counts.accumulating
    assert counts.observe(106, 194) == 0.0 and counts.step == (6, -6)    # one step known
    assert counts.observe(115, 187) == 3.0 and counts.step == (9, -7)
    assert counts.observe(115, 180) == 9.0                               # left froze
    counts.hold(9.0)
    counts.hold(3.0)
    assert counts.span_jump_ticks == 9.0                        # the largest since the reference


def test_counter_width_is_checked():
    for bits in (7, 65, 16.0):
        with pytest.raises(FilterOptionError, match=r"counter_bits must be an int in 8\.\.64"):
            EncoderCounts(counter_bits=bits)


@pytest.mark.parametrize(("change", "message"), [
    ({"reanchor_periods": 0}, "reanchor_periods must be a positive int, got 0"),
    ({"max_periods": 2.5}, "max_periods must be a positive int, got 2.5"),
    ({"max_jump_ticks": 0.0}, "max_jump_ticks must be positive, got 0.0"),
    ({"counter_bits": 7}, r"counter_bits must be an int in 8\.\.64"),
])
def test_ekf_options_are_checked_when_made(change, message):
    with pytest.raises(FilterOptionError, match=message):
        EKFOptions(**change)


def test_ekf_options_are_frozen_keyword_only_and_the_filter_keeps_them(model):
    options = EKFOptions(history=3, counter_bits=24, max_jump_ticks=4.0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        options.history = 5
    with pytest.raises(TypeError):
        EKFOptions(None)                                    # keyword-only
    ekf = ModelEKF(model, options=options, initial_ticks=(1, 2))
    assert ekf.options is options and ekf.records.maxlen == 3
    assert ekf.encoder_counts.counter_bits == 24
    assert ekf.encoder_counts.reference == ekf.encoder_counts.frame == (1, 2)
    with pytest.raises(FilterOptionError, match="options must be an EKFOptions, got dict"):
        ModelEKF(model, options={"history": 3})


def test_the_filter_differences_its_counts_once_through_them(model):
    """The EKF's reference and last frame follow the readings: a fused reading renews the
    reference, a gated one leaves it and the periods since keep counting."""
    ekf = ModelEKF(model, initial_ticks=(65530, 100))
    counts = ekf.encoder_counts
    ekf.predict(np.zeros(2))
    assert ekf.update_encoders(np.array([65530, 100])).accepted
    assert counts.reference == counts.frame == (65530, 100) and counts.periods == 0
    ekf.predict(np.zeros(2))
    assert not ekf.update_encoders(np.array([40000, 30000])).accepted      # a spike
    assert counts.reference == (65530, 100) and counts.frame == (40000, 30000)
    assert counts.step == (-25530, 29900) and counts.periods == 1          # on the ring
