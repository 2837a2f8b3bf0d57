"""What the SMAX and MuJoCo figures share: OAPPO under each reading of the paper's networks and
each gate statistic of Eq. 9, and the ablation that tests Eq. 9's selection (``study.selection``)."""
from __future__ import annotations

from oapo_lite.reuse import KL_REDUCES
from oapo_lite.study.catalogue.metrics import Metric
from oapo_lite.study.catalogue.tests import Claim

# ten seeds that chose no setting (the sweep used 0-2, Fig. 4 and the sigma rule 0-4, the
# early-reuse study 0-9)
SELECTION_SEEDS = tuple(range(10, 20))
# where reuse's cost against HAPPO's is judged (``benchmarks/reuse_cost.py``): there the ablation
# also trains its reusing curves with Algorithm 1's sampled source, the estimator at HAPPO's cost
COST_ENVS = ("smax:2s3z", "mamujoco:HalfCheetah-2x3")
# each curve trained with the sampled source, and the same with Eq. 8's weights
SAMPLED = {"oappo always sampled": "oappo always", "oappo gated sampled": "oappo gated"}
# the gate's dose-response: sigma at these quantiles of the across-network K in the runs the
# sigma rule reads (``selection.gate_sigma``; the median is the ablation's sigma), between no
# reuse (HAPPO, the gate never open) and always-on reuse (sigma = inf, never shut)
DOSE_QUANTILES = (0.25, 0.5, 0.75, 0.9)
# the readings of OAPPO's networks, as curve labels and names
READING_NAMES = {"oappo": "OAPPO (a net per agent)", "oappo type": "OAPPO (a net per type)",
                 "oappo one seat": "OAPPO (one net, seat by seat)"}


def reading_curves(env: str, networks: tuple[str, ...] = ("agent",)) -> tuple:
    """OAPPO under each networks reading in ``networks`` (a net per agent, per type) and each
    gate statistic, beside HAPPO, MAPPO and one net updated seat by seat. A reading that cannot
    change the run on an env is left out there: a net per type is a net per agent where every
    seat is its own type, and MAPPO where all are one type; one net shared by every seat is at
    KL 0 from itself, so its gate never shuts and no statistic matters."""
    return (("happo", dict(algo="happo", env=env)), ("mappo", dict(algo="mappo", env=env)),
            *((f"oappo {nets} {stat}", dict(algo="oappo", env=env, kl_reduce=stat,
                                            **({} if nets == "agent" else dict(networks=nets))))
              for nets in networks for stat in KL_REDUCES),
            ("oappo one seat", dict(algo="oappo", env=env, networks="one", update_by="seat")))


def sigma_on(table: dict, env: str) -> dict:
    """The rule's sigma per reading on ``env``, from a table keyed (env, reading)."""
    return {reading: s for (e, reading), s in table.items() if e == env}


def selection_curves(env: str, sigma: dict, per_agent: dict, per_type: dict | None = None) -> tuple:
    """The selection ablation's curves on ``env``: no reuse (HAPPO), a net per agent reusing
    always (sigma = inf) and through the gate, and with ``per_type`` a net per type reusing
    within its type only (lambda = 1) and across types through the gate. ``sigma``: the rule's
    sigma per reading ("agent", "type") on this env; a gated curve joins once it is there. On
    ``COST_ENVS`` the curves of a net per agent that reuse are trained twice (``SAMPLED``): with
    Eq. 8's weights (every source's samples, weighted by M) and with Algorithm 1's lines 5-6 (one
    source per learner and iteration drawn from M, so a learner trains on one seat's samples, as
    HAPPO's does)."""
    gated = dict(per_agent, algo="oappo", kl_reduce="mean", env=env)
    curves = [("happo", dict(per_agent, algo="happo", env=env)), ("oappo always", dict(gated, sigma=float("inf")))]
    if "agent" in sigma:
        curves.append(("oappo gated", dict(gated, sigma=sigma["agent"])))
    if env in COST_ENVS:
        weighted = dict(curves)
        curves += [(label, dict(weighted[of], reuse_mode="sample")) for label, of in SAMPLED.items() if of in weighted]
    if per_type is not None:
        by_type = dict(per_type, env=env)
        curves += [("oappo type own type", dict(by_type, reuse_lambda=1.0)),
                   ("oappo type gated", dict(by_type, sigma=sigma["type"]))]
    return tuple(curves)


def dose_curves(env: str, sigmas: tuple[float, ...], per_agent: dict) -> tuple:
    """The dose-response's curves on ``env``: no reuse (HAPPO), a net per agent gated at each
    sigma in ``sigmas`` (labelled by it), and reusing always: the selection ablation's configs, so
    that a run both figures hold is trained once."""
    ends = dict(selection_curves(env, {}, per_agent))
    gated = dict(ends["oappo always"])
    return (("happo", ends["happo"]), *((dose_label(s), dict(gated, sigma=s)) for s in sigmas),
            ("oappo always", ends["oappo always"]))


def dose_label(sigma: float) -> str:
    """A gated curve of the dose-response, by its sigma."""
    return f"oappo sigma={sigma:g}"


def selection_claims(env: str, sigma: dict, name: str, per_env: bool, metric: Metric) -> list[Claim]:
    """The ablation's claims on ``env`` (named ``name``; judged on that env's runs alone where
    ``per_env``): does reuse help, does selection, and across types; each on the final value
    seed by seed and on the speed to ``metric``'s threshold, which tells the curves apart where
    their final values sit at a ceiling."""
    on, reach = (env if per_env else None), f"reaches {metric.reach.format(metric.threshold)}"
    out = []
    if "agent" in sigma:
        gated = f"gated reuse (a net per agent, sigma {sigma['agent']:g})"
        out += [Claim(f"{name}: {gated} ends above no reuse (HAPPO)", "paired_higher", ("oappo gated", "happo"), on),
                Claim(f"{name}: {gated} {reach} before no reuse", "faster", ("oappo gated", "happo"), on),
                *selection_of("oappo gated", gated, name, on, reach)]
    out += [Claim(f"{name}: always-on reuse ends above no reuse", "paired_higher", ("oappo always", "happo"), on),
            Claim(f"{name}: always-on reuse {reach} before no reuse", "faster", ("oappo always", "happo"), on)]
    if "type" in sigma:
        across = f"a net per type reusing across types through the gate (sigma {sigma['type']:g})"
        out += [Claim(f"{name}: {across} ends above one reusing within its type only", "paired_higher",
                      ("oappo type gated", "oappo type own type"), on),
                Claim(f"{name}: {across} {reach} before one reusing within its type only", "faster",
                      ("oappo type gated", "oappo type own type"), on)]
    return out


def selection_of(label: str, gated: str, name: str, env: str | None, reach: str) -> list[Claim]:
    """The claim that the gated curve ``label`` selects: it ends above both no reuse (HAPPO) and
    always-on reuse, and ``reach``es (the metric's threshold) before both."""
    ends = ("happo", "oappo always")
    return [Claim(f"{name}: {gated} ends above both no reuse and always-on reuse (selection helps)", "selects",
                  (label, *ends), env),
            Claim(f"{name}: {gated} {reach} before both no reuse and always-on reuse", "selects_faster",
                  (label, *ends), env)]


def dose_claims(sigmas: tuple[float, ...], name: str, metric: Metric) -> list[Claim]:
    """The dose-response's claims: at each sigma, does the gate select (``selection_of``)."""
    reach = f"reaches {metric.reach.format(metric.threshold)}"
    return [c for s in sigmas for c in selection_of(dose_label(s), f"gated reuse at sigma {s:g}", name, None, reach)]
