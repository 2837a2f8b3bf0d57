"""Bad input to the study and damaged run caches: a run file is checked when read, a library call
with wrong input names it, a notebook parameter is checked in the first cell."""
import dataclasses
import os
import re
import shutil
import signal
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

import fakes
from bad_input import NOT_A_FILE, SMALL, fifo, not_a_file
from oapo_lite import store
from oapo_lite.neural.config import TrainConfig
from oapo_lite.neural.results import learning
from oapo_lite.study.catalogue import figures, grid
from oapo_lite.study.catalogue.metrics import FRAC_OPT, WIN_RATE
from oapo_lite.study.catalogue.tests import Claim
from oapo_lite.study.judge import evidence, statistics, verdicts
from oapo_lite.study.report import plotting, words
from oapo_lite.study.runs import experiments
from oapo_lite.study.studies import tables


def _cache(tmp_path, monkeypatch):
    monkeypatch.setenv("OAPO_FIGURES", str(tmp_path))
    (cfg,) = [c for _, c in figures.figure_runs("fig1", "smoke")]
    assert experiments.run_all("smoke", figures=("fig1",), workers=1, progress=False).done == 1
    return cfg, experiments.run_path(cfg, "smoke")


@pytest.mark.parametrize("damage, words", [
    (lambda df, p: p.write_bytes(b"\x89PNG\x00\xff" * 40), "damaged"),
    (lambda df, p: p.write_bytes(b""), "damaged"),
    (lambda df, p: df.iloc[:1].to_csv(p, index=False), "it has 1 rows where the config has 3 evaluations"),
    (lambda df, p: df.assign(step=df["step"].where(df.index != 1)).to_csv(p, index=False), "evaluation steps"),
    (lambda df, p: df.drop(columns="eval_return").to_csv(p, index=False), r"lacks the columns \['eval_return'\]"),
    (lambda df, p: df.assign(seed=7).to_csv(p, index=False), "another run's rows"),
    (lambda df, p: df.assign(**{"step.1": df["step"]}).to_csv(p, index=False, header=[*df.columns, "step"]),
     r"names the columns \['step'\] twice in its header"),
])
def test_the_run_cache_is_checked_when_read_and_a_damaged_run_is_trained_again(tmp_path, monkeypatch, capsys,
                                                                              damage, words):
    cfg, path = _cache(tmp_path, monkeypatch)
    good = learning(pd.read_csv(path))
    damage(pd.read_csv(path), path)
    with pytest.raises(store.DamagedFile, match=f"run file {re.escape(str(path))} .*{words}"):
        experiments.load_figure("fig1", "smoke")
    assert experiments.missing_runs("fig1", "smoke")[0].cfg == cfg
    assert f"warning: run file {path}" in capsys.readouterr().err
    count = experiments.run_all("smoke", figures=("fig1",), workers=1, progress=False)
    assert (count.done, count.cached) == (1, 0)
    pd.testing.assert_frame_equal(learning(pd.read_csv(path)), good)
    assert experiments.load_figure("fig1", "smoke")["step"].is_monotonic_increasing


def test_the_api_names_bad_arguments(tmp_path, monkeypatch):
    monkeypatch.setenv("OAPO_FIGURES", str(tmp_path))
    for label, cfg in figures.figure_runs("fig1", "smoke"):
        fakes.write_run(cfg, "smoke", lambda s: s / 400)
    assert experiments.run_all("smoke", figures="fig1", workers=1, progress=False).cached == 1  # one name is a figure
    for workers in (0, -3, "2", True):
        with pytest.raises(ValueError, match=f"workers = {re.escape(repr(workers))} is invalid"):
            experiments.run_all("smoke", figures=["fig1"], workers=workers)
    with pytest.raises(TypeError, match="must be a pandas DataFrame"):
        evidence.summary(None)
    with pytest.raises(ValueError, match=r"square \(n, n\) matrix"):
        plotting.reuse_heatmap(np.array([]))
    assert plotting.final_bars(pd.DataFrame()).texts[0].get_text() == "no runs on disk"


def test_every_notebook_names_its_kernel():
    """papermill without -k reads the kernel from the notebook."""
    import nbformat

    from oapo_lite.study.runs.reproduce import NOTEBOOKS

    for path in sorted(NOTEBOOKS.glob("[0-9]*.ipynb")):
        assert nbformat.read(path, as_version=4).metadata.get("kernelspec", {}).get("name") == "python3", path.name


def test_a_bad_budget_value_stops_the_first_cell(tmp_path):
    from oapo_lite.study.runs.reproduce import NOTEBOOKS, NotebookFailed, run_notebook

    with pytest.raises(NotebookFailed, match=r"cell 4 .*unknown budget 'nope'"):
        run_notebook(NOTEBOOKS / "10_mazes_fig3a_5a.ipynb", tmp_path / "out.ipynb", {"budget": "nope"})


def test_the_tables_take_no_rows_and_name_what_they_lack():
    from oapo_lite.study.report import claims

    none = pd.DataFrame(columns=claims.GLANCE_COLUMNS + ["n_claims", "one_seed"])
    assert claims.summary(none).empty and claims.summary_lines(none) == []
    assert claims.readme_markdown(none).endswith("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for table in (claims.summary, claims.summary_lines, claims.readme_markdown):
        with pytest.raises(ValueError, match=r"summary counts glance_table\(\)'s rows"):
            table(pd.DataFrame())
    assert tables.reuse_table(pd.DataFrame(), WIN_RATE).empty
    with pytest.raises(ValueError, match=r"no runs labelled \['a', 'b'\] to pair; the runs' labels are \[\]"):
        evidence.Evidence(pd.DataFrame()).pairs("a", "b")
    one = pd.DataFrame({"label": ["a"], "seed": [0], "step": [0], "frac_opt": [1.0]})
    with pytest.raises(ValueError, match=r"no runs of the curves \['nonexistent'\] to draw; the data's curves are "
                                         r"\['a'\]"):
        plotting.learning_curves(one, order=["nonexistent"])


@pytest.mark.parametrize("call, words", [
    (lambda: evidence.per_run(pd.DataFrame({"label": ["a"], "seed": [0], "step": [0], "frac_opt": ["x"]})),
     "'frac_opt' column holds text"),
    (lambda: evidence.per_run(pd.DataFrame(), threshold=float("nan")), "threshold = nan is invalid"),
    (lambda: evidence.per_run(pd.DataFrame(), dataclasses.replace(FRAC_OPT, tail=5)), "tail = 5 is invalid; allowed: a share"),
    (lambda: evidence.per_run(pd.DataFrame(), "frac_opt"), "metric must be a catalogue.metrics.Metric"),
    (lambda: evidence.Evidence(_two_curves().drop(columns="reuse_matrix")).pairs("a", "a"), "a and b are both 'a'"),
    (lambda: evidence.Evidence(_two_curves(b_seed=7).drop(columns="reuse_matrix")).pairs("a", "b"),
     "no seed has runs of both"),
    (lambda: tables.reuse_table(_two_curves().drop(columns="env"), FRAC_OPT), "lack the columns ['env', 'owner']"),
    (lambda: evidence.per_run(_two_curves()), "the runs hold reuse matrices but no owner column"),
    (lambda: claims_module().summary(None), "summary counts glance_table()'s rows"),
    (lambda: claims_module().summary(pd.DataFrame({"section": ["6.1"], "claim": ["c"], "verdict": ["held?"],
                                                   "n_claims": [1], "one_seed": [False]})),
     "verdicts ['held?'] that are no status"),
    (lambda: claims_module().markdown([1]), "markdown takes a DataFrame, got list"),
    (lambda: plotting.learning_curves([1]), "must be a pandas DataFrame"),
    (lambda: plotting.learning_curves(_two_curves().drop(columns="seed")), "lack the columns ['seed']"),
    (lambda: plotting.learning_curves(pd.concat([_two_curves()] * 2)), "has two rows for seed 0 at step 0"),
    (lambda: plotting.learning_curves(_two_curves().assign(frac_opt=np.nan)), "has no value of 'frac_opt' to draw"),
])
def test_a_library_call_with_wrong_input_names_it(call, words):
    with pytest.raises((ValueError, TypeError), match=re.escape(words)):
        call()


def claims_module():
    from oapo_lite.study.report import claims

    return claims


def _two_curves(b_seed: int = 0) -> pd.DataFrame:
    eye = np.eye(2)
    return pd.DataFrame({"label": ["a", "a", "b", "b"], "seed": [0, 0, b_seed, b_seed], "step": [0, 1, 0, 1],
                         "frac_opt": [0.1, 0.9, 0.2, 0.5], "env": "black_red", "reuse_matrix": [eye] * 4})


def test_markdown_keeps_a_cell_with_a_line_break_on_its_row():
    from oapo_lite.study.report import claims

    text = claims.markdown(pd.DataFrame({"a": ["one\ntwo", "x|y"]}))
    assert text.splitlines()[2:] == ["| one two |", "| x\\|y |"]


def test_a_misspelled_notebook_parameter_stops_the_first_cell_naming_it(tmp_path):
    from oapo_lite.study.runs.reproduce import NOTEBOOKS, NotebookFailed, run_notebook

    with pytest.raises(NotebookFailed, match=r"cell 4 .*unknown notebook parameter\(s\) \['budgte'\]; this "
                                             r"notebook takes \['budget'\]"):
        run_notebook(NOTEBOOKS / "10_mazes_fig3a_5a.ipynb", tmp_path / "out.ipynb", {"budgte": "smoke"})


def test_every_notebook_checks_its_parameters_right_after_them():
    import nbformat

    from oapo_lite.study.runs.reproduce import NOTEBOOKS

    for path in sorted(NOTEBOOKS.glob("[0-9]*.ipynb")):
        cells = nbformat.read(path, as_version=4).cells
        for i, cell in enumerate(cells):
            if "parameters" in cell.metadata.get("tags", []):
                names = re.findall(r"^(\w+)\s*=", cell.source, re.M)
                call = f"check_parameters({', '.join(map(repr, names))})"
                assert call in cells[i + 1].source.split("\n", 3)[2], (path.name, call)


def test_the_run_cache_refuses_another_configs_rows_and_text_in_a_number_column(tmp_path, monkeypatch):
    monkeypatch.setenv("OAPO_FIGURES", str(tmp_path))
    ten, one = (TrainConfig(algo="oappo", sigma=s, **SMALL) for s in (10.0, 1.0))
    fakes.write_run(ten, "smoke", lambda s: s / 400)
    experiments.read_run(ten, "smoke")  # whole and its own
    shutil.copy(experiments.run_path(ten, "smoke"), experiments.run_path(one, "smoke"))
    with pytest.raises(store.DamagedFile, match=r"another run's rows: its sigma column does not say 1.0"):
        experiments.read_run(one, "smoke")
    path = experiments.run_path(ten, "smoke")
    pd.read_csv(path).assign(eval_return="lots").to_csv(path, index=False)
    with pytest.raises(store.DamagedFile, match=r"its eval_return column at row 1 \(step 0\) holds 'lots'; allowed: "
                                                r"a number \(finite\); empty only where no evaluation episode ended"):
        experiments.read_run(ten, "smoke")


M_JSON = "[[0.7, 0.3], [0.3, 0.7]]"


@pytest.mark.parametrize("column, damage, words", [
    ("frac_opt", lambda v: v.where(v.index < len(v) - 4, np.nan), r"frac_opt column at row 8 \(step 1400\) is empty; allowed: a "
                                                                   r"number \(a maze's evaluation episodes always end\)"),
    ("frac_opt", lambda v: v.where(v.index != 3, np.inf), r"frac_opt column at row 4 \(step 600\) holds inf; "
                                                          r"allowed: a number <= 1.00001"),
    ("frac_opt", lambda v: v * 10, r"frac_opt column at row 3 \(step 400\) holds 2.0; allowed: a number <= 1"),
    ("frac_opt", lambda v: v * 0.5, r"frac_opt column at row 2 .* allowed: eval_return / the maze's optimum = 0.1"),
    ("eval_success", lambda v: v - 1, r"eval_success column at row 1 \(step 0\) holds -1.0; allowed: a number in "
                                      r"\[0, 1\]"),
    ("reuse_matrix", lambda v: v.where(v.index != 2, "[1]"), r"reuse_matrix column at row 3 .* allowed: a square matrix"),
    ("reuse_matrix", lambda v: v.where(v.index != 2, '"text"'), r"reuse_matrix column at row 3 \(step 400\) holds "
                                                               r"'text'; allowed: a square matrix"),
    ("reuse_matrix", lambda v: v.where(v.index != 2, "[[0.7, 0.4], [0.3, 0.7]]"), r"rows summing to 1"),
    ("reuse_matrix", lambda v: v.where(v.index != 2, "[[1, 0, 0], [0, 1, 0], [0, 0, 1]]"),
     r"the same number of seats in every matrix \(\[2, 3\] here\)"),
    ("reuse_matrix", lambda v: v.where(v.index != 2, "[[0.7, 0.3]"), r"its reuse_matrix column at row 3 holds "
                                                                    r"'\[\[0.7, 0.3\]', which is not JSON"),
    ("iteration", lambda v: v + 1, r"iteration column at row 1 \(step 0\) holds 1; allowed: step / .* = 0"),
    ("peer_share", lambda v: v.where(v.index == 0, 1.5), r"peer_share column at row 2 .* holds 1.5; allowed: a "
                                                        r"number in \[0, 1.00001\]"),
    ("value_loss", lambda v: v.where(v.index != 3, np.nan), r"value_loss column at row 4 .* empty only at the "
                                                           r"evaluation before the first iteration"),
    ("extra", lambda v: 1.0, r"columns no results row holds: \['extra'\]"),
])
def test_a_run_file_with_a_value_out_of_its_columns_range_is_refused_naming_file_column_and_row(
        tmp_path, monkeypatch, column, damage, words):
    monkeypatch.setenv("OAPO_FIGURES", str(tmp_path))
    cfg = TrainConfig(algo="oappo", **dict(SMALL, steps=2000))
    n = len(cfg.eval_steps)
    fakes.write_run(cfg, "smoke", lambda s: s / 2000, grid=1, value_loss=[np.nan] + [0.5] * (n - 1),
                    peer_share=[np.nan] + [0.3] * (n - 1), reuse_matrix=[np.nan] + [M_JSON] * (n - 1))
    experiments.read_run(cfg, "smoke")  # whole
    path = experiments.run_path(cfg, "smoke")
    df = pd.read_csv(path)
    df[column] = damage(df[column]) if column in df else damage(None)
    df.to_csv(path, index=False)
    with pytest.raises(store.DamagedFile, match=f"run file {re.escape(str(path))} .*{words}"):
        experiments.read_run(cfg, "smoke")
    assert not experiments.on_disk(cfg, "smoke")  # so reproduce trains it again


def test_an_engine_evaluation_may_be_empty_and_every_verdict_says_so():
    runs = pd.DataFrame({"label": ["a"] * 8 + ["b"] * 8, "seed": ([0] * 4 + [1] * 4) * 2,
                         "step": list(range(4)) * 4,
                         "eval_success": [0, .5, .9, np.nan, 0, .5, .9, 1, 0, .1, .1, .1, 0, .1, .2, .1]})
    rows = evidence.per_run(runs, dataclasses.replace(WIN_RATE, tail=0.5))
    # the window: 3 evaluations at least, of those that hold a value
    assert rows["gaps"].tolist() == [1, 0, 0, 0] and rows["final"].iloc[0] == pytest.approx(np.mean([0, 0.5, 0.9]))
    v = verdicts.check(evidence.Evidence(runs, WIN_RATE), Claim("a ends above b", "higher", ("a", "b")))
    assert v.empty == (("a", 1),)
    assert words.reason(v).endswith("1 of a's evaluations hold no value (no evaluation episode ended) and are left out")
    with pytest.raises(ValueError, match=r"curve 'a' has two rows for seed 0 at step 1"):
        evidence.per_run(pd.concat([runs, runs.iloc[[1]]]), WIN_RATE)


def test_reading_results_never_writes(tmp_path, monkeypatch):
    monkeypatch.setenv("OAPO_FIGURES", str(tmp_path))
    for label, cfg in figures.figure_runs("fig1", "smoke"):
        fakes.write_run(cfg, "smoke", lambda s: s / 400)
    written = []
    monkeypatch.setattr(store, "atomic_write", lambda *a: written.append(a))
    assert len(experiments.load_figure("fig1", "smoke")) and written == []
    monkeypatch.undo()
    monkeypatch.setenv("OAPO_FIGURES", str(tmp_path))
    assert experiments.export_figure("fig1", "smoke") == experiments.data_dir("smoke") / "fig1.csv"
    assert experiments.export_figure("fig1", "smoke") is None  # unchanged: left alone


def test_the_statistics_take_a_frame_with_no_run(tmp_path):
    empty = pd.DataFrame()
    assert evidence.per_run(empty).empty and list(evidence.per_run(empty).columns) == evidence.PER_RUN_COLUMNS
    assert evidence.summary(empty).empty and evidence.intervals(empty).empty and tables.reuse_summary(empty).empty
    assert plotting.learning_curves(empty).texts[0].get_text() == "no runs on disk"
    assert np.isnan(statistics.probability_of_improvement([np.nan, np.nan], [1, 2]))
    assert statistics.probability_of_improvement([3, 1], [1, 2]) == 0.625  # (1 + 0.5 + 0 + 1) / 4: brute force


# ---------------------------------------------------------------- issue 53: a run file that is no file


@pytest.mark.parametrize("kind", ["FIFO", "socket", "link to a device"])
def test_a_run_file_that_is_no_regular_file_is_named_and_never_opened(tmp_path, monkeypatch, capsys, kind):
    """load_figure read a FIFO in place of a cached run's CSV for ever; so did the plan."""
    from oapo_lite.study.runs import costs

    monkeypatch.setenv("OAPO_FIGURES", str(tmp_path))
    (cfg,) = [c for _, c in figures.figure_runs("fig1", "smoke")]
    path = experiments.run_path(cfg, "smoke")
    path.parent.mkdir(parents=True)
    what = NOT_A_FILE[kind]
    with not_a_file(path, kind):
        for call in (lambda: experiments.load_figure("fig1", "smoke"), lambda: experiments.missing_runs("fig1", "smoke"),
                     lambda: costs.plan("smoke", ["fig1"])):
            with pytest.raises(store.NotAFile, match=re.escape(f"run file {path} is {what}, not a file; delete or move")):
                call()


def test_a_figure_csv_and_a_cost_table_that_are_no_files_are_named(tmp_path, monkeypatch):
    from oapo_lite.study.runs import costs

    monkeypatch.setenv("OAPO_FIGURES", str(tmp_path))
    for label, cfg in figures.figure_runs("fig1", "smoke"):
        fakes.write_run(cfg, "smoke", lambda s: s / 400)
    with fifo(experiments.data_dir("smoke") / "fig1.csv") as path:
        with pytest.raises(store.NotAFile, match=re.escape(f"figure file {path} is a FIFO (named pipe)")):
            experiments.export_figure("fig1", "smoke")
    with fifo(tmp_path / "costs.csv") as path:
        with pytest.raises(store.NotAFile, match=re.escape(f"cost table {path} is a FIFO (named pipe)")):
            costs.table(path)


# ---------------------------------------------------------------- issue 53: a name that names nothing


@pytest.mark.parametrize("figure, budget, words", [
    ("fig4_smax", "student", "figure 'fig4_smax' has no runs at budget 'student'; it has runs at ['smoke', 'paper', "
                             "'cpu']"),
    ("fig5b", "student", "figure 'fig5b' has no runs at budget 'student'; it has runs at ['smoke', 'paper', 'paper20', "
                         "'cpu']"),  # left out by the budget, not by the figure
    ("fig_dose_smax", "smoke", "figure 'fig_dose_smax' has no runs at budget 'smoke'; it has runs at ['cpu']"),
    ("fig1", "Student", "unknown budget 'Student'; choose from"),
    ("fig_1", "smoke", "unknown figure 'fig_1'; choose from"),
])
def test_a_figure_without_runs_at_a_budget_is_refused_not_read_as_empty(capsys, figure, budget, words):
    """load_figure('fig4_smax', 'student') returned an empty frame without a word. A notebook that
    shows what is on disk (skip_missing) gets the empty frame, and the words."""
    with pytest.raises(ValueError, match=re.escape(words)):
        experiments.load_figure(figure, budget)
    if not words.startswith("figure"):  # a name that names nothing is refused either way
        with pytest.raises(ValueError, match=re.escape(words)):
            experiments.load_figure(figure, budget, skip_missing=True)
        return
    assert experiments.load_figure(figure, budget, skip_missing=True).empty
    assert f"warning: {words}" in capsys.readouterr().out
    with pytest.raises(ValueError, match=re.escape(words)):  # the reader beneath it, and the trainer of named figures
        experiments.read_figure(figure, budget)
    with pytest.raises(ValueError, match=re.escape(words)):
        experiments.run_all(budget, [figure], workers=1, progress=False)
    if words.startswith("figure"):  # the catalogue itself: which budgets train it
        assert [b for b in ("smoke", "paper", "paper20", "cpu", "student")
                if figures.runs_of(figure, b)] == eval(words.rsplit("it has runs at ", 1)[1])
        with pytest.raises(ValueError, match=re.escape(words)):
            verdicts.at_budget(figures.get_figure(figure), budget, required=True)


# ---------------------------------------------------------------- issue 53: a string, a bool


@pytest.mark.parametrize("call, error, words", [
    (lambda: experiments.load_figure("fig1", "smoke", skip_missing="no"), TypeError,
     "skip_missing must be True or False, got 'no'"),
    (lambda: experiments.read_figure("fig1", "smoke", skip_missing=1), TypeError, "skip_missing must be True or False, got 1"),
    (lambda: experiments.run_all("smoke", ["fig1"], progress="no"), TypeError,
     "run_all's progress must be True, False or \"lines\", got 'no'"),
    (lambda: experiments.train_runs("smoke", "fig1"), TypeError, "train_runs' figures must be a sequence of names, got the "
                                                                 "string 'fig1'"),
    (lambda: experiments.grid_runs("smoke", "fig1"), TypeError, "figures must be a sequence of names, got the string"),
    (lambda: costs_module().plan("smoke", "fig1"), TypeError, "figures must be a sequence of names, got the string"),
    (lambda: costs_module().plan("smoke", ["fig1"], from_nothing="no"), TypeError,
     "from_nothing must be True or False, got 'no'"),
    (lambda: verdicts.at_budget(figures.get_figure("fig3b"), "cpu", required="yes"), TypeError,
     "at_budget's required must be True or False, got 'yes'"),
    (lambda: verdicts.glance("cpu"), TypeError, "budgets must be a sequence of names, got the string 'cpu'"),
    (lambda: grid.get_budget(["smoke"]), ValueError, "unknown budget ['smoke'] (a list, where a budget is one name); "
                                                     "choose from"),
    (lambda: grid.get_budget(None), ValueError, "unknown budget None (a NoneType, where a budget is one name)"),
])
def test_a_string_for_a_sequence_and_a_non_bool_for_a_bool_are_refused(tmp_path, monkeypatch, call, error, words):
    """Read as truthy, skip_missing="no" meant yes; a string of figures was split into letters;
    papermill's -y "budget: [smoke]" ended in TypeError: unhashable type: 'list'."""
    monkeypatch.setenv("OAPO_FIGURES", str(tmp_path))
    with pytest.raises(error, match=re.escape(words)):
        call()


def costs_module():
    from oapo_lite.study.runs import costs

    return costs


def test_a_budget_that_is_no_name_stops_the_first_cell(tmp_path):
    from oapo_lite.study.runs.reproduce import NOTEBOOKS, NotebookFailed, run_notebook

    with pytest.raises(NotebookFailed, match=r"cell 4 .*unknown budget \['smoke'\] \(a list, where a budget is one name"):
        run_notebook(NOTEBOOKS / "10_mazes_fig3a_5a.ipynb", tmp_path / "out.ipynb", {"budget": ["smoke"]})


# ---------------------------------------------------------------- issue 53: values in memory and over time


@pytest.mark.parametrize("column", ["cpu_s", "wall_s"])
def test_a_cumulative_cost_that_falls_is_refused_on_read_and_in_memory(tmp_path, monkeypatch, column):
    """A cpu_s that fell loaded without a word and priced the plan."""
    from oapo_lite.study.runs import costs

    monkeypatch.setenv("OAPO_FIGURES", str(tmp_path))
    cfg = TrainConfig(algo="oappo", **dict(SMALL, steps=2000))
    n = len(cfg.eval_steps)
    sums = np.arange(1.0, n + 1)
    fell = sums.copy()
    fell[4] = 2.5  # below row 4's 4.0
    fakes.write_run(cfg, "smoke", lambda s: s / 2000, grid=1, cpu_s=sums, wall_s=sums)
    experiments.read_run(cfg, "smoke")  # rising: whole
    assert costs.recorded([(cfg, experiments.read_run(cfg, "smoke"))])  # and priced
    fakes.write_run(cfg, "smoke", lambda s: s / 2000, grid=1, **{"cpu_s": sums, "wall_s": sums, column: fell})
    words = rf"its {column} column at row 5 \(step 800\) holds 2.5; allowed: a number >= 4.0, its value at an earlier step"
    with pytest.raises(store.DamagedFile, match=words):
        experiments.read_run(cfg, "smoke")
    frame = pd.DataFrame({"step": cfg.eval_steps, "cpu_s": sums, "wall_s": sums}).assign(**{column: fell})
    with pytest.raises(ValueError, match=words):
        costs.recorded([(cfg, frame)])


@pytest.mark.parametrize("change, words", [
    (lambda df: df.assign(frac_opt=df["frac_opt"] * 10), r"its frac_opt column at row \d+ \(step \d+\) holds [\d.]+; "
                                                          r"allowed: a number <= 1.00001"),
    (lambda df: df.assign(eval_success=df["eval_success"] + 1), r"its eval_success column .* allowed: a number in \[0, 1\]"),
    (lambda df: df.assign(frac_opt=-5.0), r"its frac_opt column at row 1 \(step 0\) holds -5.0; allowed: eval_return / "
                                          r"the maze's optimum = "),  # in range, but not the return's fraction
    (lambda df: df.assign(seed=df["seed"].astype(float) + 0.5), None),  # not a column a run's results declare
])
def test_judge_checks_a_frame_as_the_reader_checks_a_run_file(change, words):
    """frac_opt x 10 in memory changed the verdicts; the reader would have refused the file."""
    df = experiments.load_figure("fig3b", "paper")
    before = [v.status for v in verdicts.judge("fig3b", df)]
    if words is None:
        verdicts.judge("fig3b", change(df))
        return
    with pytest.raises(ValueError, match=f"the runs of fig3b given to judge are not what runs write: {words}"):
        verdicts.judge("fig3b", change(df))
    assert [v.status for v in verdicts.judge("fig3b", df)] == before


# ---------------------------------------------------------------- issue 53: a rerun after kill -9 matches


KILLED_DRIVER = """
import os, signal, sys
from oapo_lite.study.runs import executors, experiments
at, real = int(sys.argv[1]), executors.train

def train(cfg, out, callback, **kw):  # killed right after iteration ``at`` (and its checkpoint, if any)
    return real(cfg, out, callback=lambda m: callback(m) or (m["iteration"] == at and os.kill(os.getpid(), 9)), **kw)

executors.train = train
experiments.run_all("smoke", figures=("fig1",), workers=1, progress=False)
"""


@pytest.mark.parametrize("at", [1, 2], ids=["mid-run, before any checkpoint", "after the last checkpoint"])
def test_a_reproduce_killed_and_rerun_writes_the_uninterrupted_files(tmp_path, at):
    """Every run file and the figure's CSV equal the uninterrupted ones on every column but the
    measured costs (``results.learning``, ASSUMPTIONS.md)."""
    whole, killed = tmp_path / "whole", tmp_path / "killed"
    for folder, code, args in ((whole, "from oapo_lite.study.runs import experiments; experiments.run_all('smoke', "
                                       "figures=('fig1',), workers=1, progress=False)", []),
                               (killed, KILLED_DRIVER, [str(at)])):
        done = subprocess.run([sys.executable, "-c", code, *args], env={**os.environ, "OAPO_FIGURES": str(folder)},
                              capture_output=True, text=True, timeout=600)
        assert done.returncode == (-signal.SIGKILL if folder == killed else 0), done.stderr
    rerun = subprocess.run([sys.executable, "-c", "from oapo_lite.study.runs import experiments; c = experiments.run_all("
                            "'smoke', figures=('fig1',), workers=1, progress=False); print(c.done, c.cached)"],
                           env={**os.environ, "OAPO_FIGURES": str(killed)}, capture_output=True, text=True, timeout=600)
    assert rerun.stdout.split() == ["1", "0"], rerun.stderr  # trained, or written again from its checkpoint
    files = sorted(p.relative_to(whole) for p in whole.rglob("*.csv") if "checkpoints" not in p.parts)
    assert len(files) == 2 and files == sorted(p.relative_to(killed) for p in killed.rglob("*.csv")
                                               if "checkpoints" not in p.parts)
    for name in files:
        pd.testing.assert_frame_equal(learning(pd.read_csv(whole / name)), learning(pd.read_csv(killed / name)))
