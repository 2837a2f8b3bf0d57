"""The study's statistics against rliable's, the library RL papers report with, on the committed
runs: the same IQM and probability of improvement, and percentile bootstrap intervals within
bootstrap noise (the two draw their resamples from different generators).

rliable 1.2.0 (the current release) passes ``random_state`` to arch's bootstraps, a keyword arch 8
renamed to ``seed`` (arch 7, which takes it, does not import beside pandas 3); the fixture drops it,
so rliable's resamples come from numpy's global generator, as its ``update_indices`` draws them."""
import numpy as np
import pytest
from scipy import stats

from oapo_lite.study.catalogue import figures
from oapo_lite.study.judge.evidence import Evidence
from oapo_lite.study.judge.statistics import N_RESAMPLES, SEED, bootstrap_interval, iqm, probability_of_improvement
from oapo_lite.study.runs import experiments

rliable = pytest.importorskip("rliable.library")
metrics = pytest.importorskip("rliable.metrics")


@pytest.fixture(autouse=True)
def _arch_takes_rliables_keyword(monkeypatch):
    import arch.bootstrap as bootstrap

    for cls in (bootstrap.IIDBootstrap, bootstrap.IndependentSamplesBootstrap):
        original = cls.__init__
        monkeypatch.setattr(cls, "__init__", lambda self, *a, random_state=None, _init=original, **k: _init(self, *a, **k))


def theirs(scores, statistic):
    """rliable's point estimate and 95% percentile interval of ``statistic`` on ``scores``
    (an array of runs, or a tuple of two for a pair), one task, as many resamples as ours."""
    np.random.seed(0)
    key = "x"
    point, interval = rliable.get_interval_estimates({key: scores}, statistic, reps=N_RESAMPLES)
    return float(np.squeeze(point[key])), float(np.squeeze(interval[key][0])), float(np.squeeze(interval[key][1]))


def close(statistic, samples, point, low, high) -> bool:
    """Ours equal rliable's within bootstrap noise: the same point estimate, and rliable's interval
    ends at levels of our own bootstrap distribution within 1% of 2.5% and 97.5% (six standard
    errors of a quantile's level at 10,000 resamples; with few seeds the distribution is lumpy, so
    two generators' ends may sit on neighbouring lumps)."""
    ours = bootstrap_interval(statistic, *samples)
    dist = stats.bootstrap(samples, statistic, n_resamples=N_RESAMPLES, method="percentile", vectorized=True,
                           rng=np.random.default_rng(SEED)).bootstrap_distribution
    level = lambda x: (np.mean(dist < x - 1e-9), np.mean(dist <= x + 1e-9))  # noqa: E731  the levels x takes
    lo, hi = level(low), level(high)
    return (np.isclose(ours.point, point, rtol=0, atol=1e-9) and lo[0] <= 0.035 and lo[1] >= 0.015
            and hi[0] <= 0.985 and hi[1] >= 0.965)


CASES = [("fig3b", "paper20", None), ("fig_selection_smax", "cpu", "smax:2s3z")]  # 20 seeds; 10 seeds, paired


@pytest.mark.parametrize("figure, budget, env", CASES)
def test_iqm_and_its_interval_are_rliables_on_the_committed_runs(figure, budget, env):
    df = experiments.read_figure(figure, budget)[0]
    ev = Evidence(df if env is None else df[df["env"] == env], figures.get_figure(figure).metric)
    for label in ev.labels:
        finals = ev.run_values(label, "final")
        aggregate = lambda s: np.array([metrics.aggregate_iqm(s)])  # noqa: E731
        assert close(iqm, (finals,), *theirs(finals[:, None], aggregate)), label


@pytest.mark.parametrize("figure, budget, env", CASES)
def test_probability_of_improvement_is_rliables_on_every_claimed_pair(figure, budget, env):
    fig = figures.get_figure(figure)
    df = experiments.read_figure(figure, budget)[0]
    ev = Evidence(df if env is None else df[df["env"] == env], fig.metric)
    pairs = {c.curves[:2] for c in fig.claims if len(c.curves) >= 2 and (env is None or c.env == env)}
    assert pairs
    for a, b in sorted(pairs, key=str):
        x, y = ev.run_values(a, "final"), ev.run_values(b, "final")
        assert close(probability_of_improvement, (x, y), *theirs((x[:, None], y[:, None]),
                                                                  metrics.probability_of_improvement)), (a, b)
        if set(ev.seeds(a, b)) == set(ev.runs["seed"]):  # paired: the IQM of each seed's own difference
            d = ev.pairs(a, b)["difference"].to_numpy()
            assert ev.paired(a, b) == bootstrap_interval(iqm, d)
            assert close(iqm, (d,), *theirs(d[:, None], lambda s: np.array([metrics.aggregate_iqm(s)]))), (a, b)
