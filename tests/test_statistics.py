"""training/judging/statistics.py against known values: Wilson and Student t, the stratified bootstrap of
a group of training seeds, and the across-task measures (IQM, probability of improvement,
performance profiles)."""

from __future__ import annotations

import time

import numpy as np
import pytest

from training.judging import statistics as st


def test_wilson_and_the_t_quantile_match_known_values():
    assert st.wilson(24, 30) == pytest.approx((0.6269, 0.9049), abs=1e-4)  # the 0.63-0.90
    assert st.wilson(10, 10) == pytest.approx((0.7225, 1.0), abs=1e-4)
    assert st.wilson(0, 10) == pytest.approx((0.0, 0.2775), abs=1e-4)
    assert all(np.isnan(st.wilson(0, 0)))
    assert st.t_quantile(31) == pytest.approx(2.0395, abs=1e-4)  # the old table said 2.021
    assert st.t_quantile(1) == pytest.approx(12.706, abs=1e-3)
    assert st.t_quantile(9) == pytest.approx(2.262, abs=1e-3)
    assert np.isnan(st.t_quantile(0))


def test_mean_ci_is_the_student_t_interval():
    mean, half = st.mean_ci([1.0, 2.0, 3.0, 4.0])
    assert mean == 2.5 and half == pytest.approx(3.1824 * np.std([1, 2, 3, 4], ddof=1) / 2, abs=1e-3)
    assert st.mean_ci([5.0])[0] == 5.0 and np.isnan(st.mean_ci([5.0])[1])
    assert all(np.isnan(st.mean_ci([])))


def _kickstart_on_grasp():
    """Three training seeds of ten episodes, each 8/10 (the study's kickstart on grasp, 24/30)."""
    successes = [[True] * 8 + [False] * 2] * 3
    cycles = [[153] * 4 + [150] * 4 + [300] * 2, [94, 90, 98, 94, 94, 93, 95, 94, 300, 300], [114] * 8 + [300] * 2]
    return successes, cycles


def test_the_group_bootstrap_of_three_seeds_of_24_30_is_an_interval_around_the_pooled_rate():
    successes, cycles = _kickstart_on_grasp()
    out = st.group_bootstrap(successes, cycles, cycles)
    assert out["success_rate"] == pytest.approx(0.8)
    assert out["success_lo"] < 0.8 < out["success_hi"]  # not "0.80 ± 0.00"
    assert out["success_hi"] - out["success_lo"] > 0.15
    won = [c for cs, ss in zip(cycles, successes) for c, s in zip(cs, ss) if s]
    assert out["cycles_to_success"] == pytest.approx(np.mean(won))
    assert out["cycles_lo"] < np.mean(won) < out["cycles_hi"]
    assert 90 <= out["cycles_lo"] and out["cycles_hi"] <= 153  # a seed's mean bounds the pooled one
    assert out["return_lo"] < out["return_mean"] < out["return_hi"]
    assert st.group_bootstrap(successes, cycles, cycles) == out  # a fixed generator seed


def test_the_group_bootstrap_resamples_training_seeds_and_handles_ragged_and_degenerate_groups():
    # seeds that disagree: the interval spans them, where pooling the episodes alone would not
    apart = st.group_bootstrap([[True] * 10, [False] * 10, [True] * 10], [[50] * 10, [300] * 10, [60] * 10])
    assert apart["success_rate"] == pytest.approx(2 / 3)
    assert apart["success_lo"] <= 1 / 3 + 1e-9 and apart["success_hi"] == 1.0
    # seeds with different numbers of episodes
    ragged = st.group_bootstrap([[True, False, True], [False] * 7], [[5, 9, 7], [9] * 7])
    assert ragged["success_rate"] == pytest.approx(0.2) and ragged["cycles_to_success"] == pytest.approx(6.0)
    assert 0.0 <= ragged["success_lo"] < ragged["success_hi"] <= 1.0
    # no success: no cycles to success; one success: no cycles interval
    none = st.group_bootstrap([[False] * 5] * 3, [[9] * 5] * 3)
    assert none["success_rate"] == 0.0 and np.isnan(none["cycles_to_success"]) and np.isnan(none["cycles_lo"])
    one = st.group_bootstrap([[True] + [False] * 4, [False] * 5], [[7] + [9] * 4, [9] * 5])
    assert one["cycles_to_success"] == 7.0 and np.isnan(one["cycles_lo"]) and np.isnan(one["return_mean"])
    with pytest.raises(ValueError, match="same shape"):
        st.group_bootstrap([[True, False]], [[5]])
    with pytest.raises(ValueError, match="one non-empty sequence"):
        st.group_bootstrap([], [])


def test_the_group_bootstrap_is_vectorised():
    rng = np.random.default_rng(0)
    successes = [rng.random(50) < 0.7 for _ in range(10)]
    cycles = [rng.integers(40, 300, 50) for _ in range(10)]
    started = time.perf_counter()
    st.group_bootstrap(successes, cycles, cycles)
    assert time.perf_counter() - started < 2.0  # 2,000 resamples of 10 seeds x 50 episodes


def test_normalised_scores_put_random_at_0_and_the_rules_at_1():
    scores = st.normalized_score([[0.2, 0.5, 0.9], [0.6, 0.5, 0.1]], [0.2, 0.5, 0.1], [1.0, 0.5, 0.9])
    assert scores[:, 0] == pytest.approx([0.0, 0.5]) and scores[:, 2] == pytest.approx([1.0, 0.0])
    assert np.isnan(scores[:, 1]).all()  # rules == random: the task has no scale


def test_the_iqm_of_a_hand_made_array_and_its_interval():
    scores = np.arange(1.0, 9.0).reshape(4, 2)  # 1..8: the middle half is 3, 4, 5, 6
    assert st.iqm(scores) == pytest.approx(4.5)
    assert st.iqm([[0.0, 100.0], [1.0, 2.0], [2.0, 3.0], [3.0, -50.0]]) == pytest.approx(2.0)  # outliers cut
    value, lo, hi = st.iqm_ci(scores)
    assert value == pytest.approx(4.5) and lo < 4.5 < hi
    assert st.iqm_ci(np.ones((5, 3))) == pytest.approx((1.0, 1.0, 1.0))
    # a task without a scale is left out
    assert st.iqm(np.column_stack([scores, np.full(4, np.nan)])) == pytest.approx(4.5)
    with pytest.raises(ValueError, match="no task with a defined normalised score"):
        st.iqm(np.full((3, 2), np.nan))


def test_the_probability_of_improvement_of_separated_and_identical_samples():
    rng = np.random.default_rng(0)
    better, worse = rng.normal(5.0, 0.1, (5, 4)), rng.normal(0.0, 0.1, (6, 4))
    assert st.probability_of_improvement(better, worse) == pytest.approx(1.0)
    assert st.probability_of_improvement(worse, better) == pytest.approx(0.0)
    same = rng.normal(size=(5, 3))
    assert st.probability_of_improvement(same, same) == pytest.approx(0.5)  # ties count half
    assert st.probability_of_improvement(np.ones((3, 2)), np.ones((1, 2))) == pytest.approx(0.5)
    # against the Mann-Whitney U statistic of scipy, one task
    from scipy.stats import mannwhitneyu

    x, y = rng.integers(0, 4, (7, 1)).astype(float), rng.integers(0, 4, (5, 1)).astype(float)
    u = mannwhitneyu(x[:, 0], y[:, 0]).statistic
    assert st.probability_of_improvement(x, y) == pytest.approx(u / 35)
    value, lo, hi = st.probability_of_improvement_ci(better, worse)
    assert (value, lo, hi) == pytest.approx((1.0, 1.0, 1.0))
    value, lo, hi = st.probability_of_improvement_ci(x, y)
    assert lo <= value <= hi and lo < hi


def test_performance_profiles_with_bands():
    scores = np.array([[0.0, 0.5], [1.0, 1.5], [0.25, 2.0]])
    profile, lo, hi = st.performance_profile(scores, [-1.0, 0.0, 0.75, 1.0, 3.0])
    assert profile == pytest.approx([1.0, 5 / 6, 3 / 6, 2 / 6, 0.0])
    assert (lo <= profile + 1e-12).all() and (profile <= hi + 1e-12).all()
    assert lo[0] == hi[0] == 1.0 and lo[-1] == hi[-1] == 0.0
    assert profile.shape == lo.shape == hi.shape == (5,)


def test_the_paired_difference_of_identical_and_shifted_controllers():
    reference = np.array([1.0, 0.0, 1.0, 1.0])
    same = st.paired_difference(np.tile(reference, (3, 1)), reference)
    assert (same["difference"], same["lo"], same["hi"], same["p"], same["pairs"]) == (0.0, 0.0, 0.0, 1.0, 12)
    worse = st.paired_difference(np.tile(reference - 1.0, (3, 1)), reference)
    assert (worse["difference"], worse["lo"], worse["hi"], worse["p"]) == (-1.0, -1.0, -1.0, 0.0)


def test_the_paired_bootstrap_draws_training_seeds_as_well_as_worlds():
    """One seed always succeeds and one always fails where the reference succeeds on half the
    worlds: the mean difference is 0, but a new training seed could be either, so the interval
    spans most of -0.5 to 0.5 (a bootstrap of worlds alone would give 0 to 0)."""
    reference = np.array([1.0, 0.0] * 10)
    x = np.stack([np.ones(20), np.zeros(20)])
    d = st.paired_difference(x, reference)
    assert d["difference"] == 0.0 and d["lo"] <= -0.4 and d["hi"] >= 0.4 and d["p"] > 0.5


def test_the_paired_difference_keeps_only_the_masked_pairs():
    """Cycles compared where both succeeded: the pairs the mask drops do not count, and a
    resample that draws none of the kept pairs is left out."""
    x = np.array([[50.0, 300.0, 80.0], [60.0, 300.0, 70.0]])
    reference = np.array([70.0, 90.0, 300.0])
    keep = np.array([[True, False, False], [True, False, False]])
    d = st.paired_difference(x, reference, keep)
    assert d["pairs"] == 2 and d["difference"] == pytest.approx(-15.0)
    assert -20.0 <= d["lo"] <= d["hi"] <= -10.0
    none = st.paired_difference(x, reference, np.zeros_like(keep))
    assert none["pairs"] == 0 and np.isnan(none["difference"])


@pytest.mark.parametrize(
    "x, reference", [(np.ones(3), np.ones(3)), (np.ones((2, 3)), np.ones(4)), (np.ones((0, 3)), np.ones(3))]
)
def test_the_paired_difference_refuses_shapes_that_do_not_pair(x, reference):
    with pytest.raises(ValueError, match="paired_difference"):
        st.paired_difference(x, reference)


def test_ties_can_be_counted_apart_and_whole_runs_resampled_together():
    same = np.array([[0.5, 1.0], [0.5, 1.0]])
    assert st.probability_of_improvement(same, same) == 0.5
    assert st.probability_of_improvement(same, same, ties=0.0) == 0.0
    assert st.probability_of_improvement(same, same, ties=1.0) == 1.0
    # splits that share each training seed's checkpoint: a joint resample keeps a seed's row whole
    rows = np.array([[0.0, 0.0], [1.0, 1.0]])
    boot = st._resample_runs(rows, np.random.default_rng(0), 200, joint=True)
    assert (boot[..., 0] == boot[..., 1]).all()
    apart = st._resample_runs(rows, np.random.default_rng(0), 200)
    assert (apart[..., 0] != apart[..., 1]).any()
    # so the interval of the IQM of two perfectly correlated splits is at least as wide jointly
    _, lo_joint, hi_joint = st.iqm_ci(np.repeat(np.array([[0.0], [0.4], [0.6], [1.0]]), 3, axis=1), joint=True)
    _, lo_apart, hi_apart = st.iqm_ci(np.repeat(np.array([[0.0], [0.4], [0.6], [1.0]]), 3, axis=1))
    assert hi_joint - lo_joint >= hi_apart - lo_apart


def test_equivalence_needs_the_90_percent_interval_inside_the_margin():
    """Two one-sided tests: the same successes on 100 worlds x 10 seeds are within 0.05; a shift
    of 0.2 is not; and 2 seeds on 10 noisy worlds are neither detectably different nor shown
    equivalent (the interval is too wide to say either)."""
    rng = np.random.default_rng(3)
    reference = (rng.random(100) < 0.8).astype(float)
    same = st.equivalence(np.tile(reference, (10, 1)), reference, 0.05)
    assert same["equivalent"] and same["lo"] == same["hi"] == 0.0 and same["margin"] == 0.05
    shifted = np.tile(reference, (10, 1))
    shifted[:, :20] = 0.0  # 20 of the worlds lost
    assert not st.equivalence(shifted, reference, 0.05)["equivalent"]
    noisy = (rng.random((2, 10)) < 0.8).astype(float)
    test = st.equivalence(noisy, reference[:10], 0.05)
    assert not test["equivalent"] and test["hi"] - test["lo"] > 0.1
    wide = st.paired_difference(noisy, reference[:10])  # its 95 % interval holds the 90 % one
    assert wide["lo"] <= test["lo"] and test["hi"] <= wide["hi"]
    with pytest.raises(ValueError, match="margin"):
        st.equivalence(noisy, reference[:10], 0.0)


def test_the_interval_of_one_new_seed_is_wider_than_that_of_the_mean_and_covers_new_seeds():
    rates = [0.91, 0.83, 0.94, 0.95, 0.86, 0.88, 0.91, 0.88, 0.88, 0.90]
    mean, lo, hi = st.new_seed_interval(rates)
    half = st.t_quantile(9) * np.std(rates, ddof=1) * np.sqrt(1 + 1 / 10)
    assert (mean, lo, hi) == pytest.approx((0.894, 0.894 - half, 0.894 + half))
    assert hi - lo > 2 * st.mean_ci(rates)[1] * 3  # sqrt(n + 1) times the mean's interval
    assert st.new_seed_interval([0.8, 0.9, 1.0]) == pytest.approx((0.9, 0.403, 1.0), abs=1e-3)  # clipped at 1
    assert np.isnan(st.new_seed_interval([0.5])[1])
    # ten seeds drawn from one spread, then one more: the new one lands inside about 95 % of the time
    rng = np.random.default_rng(0)
    draws = rng.normal(0.7, 0.05, size=(4000, 11))
    inside = [lo <= d[10] <= hi for d in draws for _, lo, hi in [st.new_seed_interval(d[:10])]]
    assert 0.93 < np.mean(inside) < 0.97
