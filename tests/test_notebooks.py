"""What the committed notebooks print, read as text: no check of a number the text quotes says
False, and the numeric paths that ``make test`` runs nbval under are other kernels, each one
(``numeric_paths.py``)."""
import os
import subprocess
import sys
from pathlib import Path

import nbformat
import pytest
import torch

from oapo_lite.study.catalogue import figures
from oapo_lite.study.report import quoted

import numeric_paths

NOTEBOOKS = sorted((Path(__file__).resolve().parent.parent / "notebooks").glob("*.ipynb"))


def printed_lines(notebook: Path) -> list[str]:
    """Every line a committed notebook printed (streams and plain-text results)."""
    lines = []
    for cell in nbformat.read(notebook, as_version=4).cells:
        for out in cell.get("outputs", ()):
            text = out.get("text") or out.get("data", {}).get("text/plain", "")
            lines += "".join(text).splitlines()
    return lines


def test_no_committed_notebook_prints_a_failed_check_of_its_quoted_numbers():
    checks = {nb.name: [line for line in printed_lines(nb) if line.startswith(quoted.PREFIX)] for nb in NOTEBOOKS}
    assert checks["05_oatrpo_oappo_eq7_9.ipynb"], "notebook 05 checks the numbers it quotes with quoted.check"
    failed = {name: quoted.failed(lines) for name, lines in checks.items() if quoted.failed(lines)}
    assert not failed, f"a committed notebook says a quoted number is wrong: {failed}"


def test_a_quoted_check_says_false_and_is_found(capsys):
    quoted.check("K", [[0, 0.0263]], [[0, 0.0263]], rtol=0.01)
    quoted.check("ratio", 1.05, 1.0, rtol=0.01)
    quoted.check("two", [0.5, 2.0], [0.5, 1.0], rtol=0.01)  # one entry out is out
    quoted.check("near 0", 0.0004, 0.0, rtol=0.01, atol=0.0005)
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == "as quoted: K [[0.0, 0.0263]] (to 1% relative): True"
    assert lines[3] == "as quoted: near 0 0.0 (to 1% relative + 0.0005): True"
    assert quoted.failed(lines) == lines[1:3] and lines[1].endswith("False")
    with pytest.raises(ValueError, match="shape"):  # numpy would broadcast one quoted number over two values
        quoted.check("short", [1.0, 1.0], [1.0], rtol=0.01)


def test_the_nbval_report_counts_compared_cells_and_moved_ones(tmp_path):
    nb = nbformat.v4.new_notebook()
    out = [nbformat.v4.new_output("stream", text="1\n")]
    nb.cells = [nbformat.v4.new_code_cell("print(1)", outputs=out),
                nbformat.v4.new_code_cell("# NBVAL_IGNORE_OUTPUT\nprint(1)", outputs=out),
                nbformat.v4.new_code_cell("print(1)", outputs=out, metadata={"tags": ["nbval-ignore-output"]}),
                nbformat.v4.new_code_cell("x = 1"),
                nbformat.v4.new_markdown_cell("text")]
    nbformat.write(nb, tmp_path / "a.ipynb")
    assert numeric_paths.compared_cells(tmp_path / "a.ipynb") == 1
    (tmp_path / "j.xml").write_text(
        '<testsuites><testsuite><testcase classname="notebooks.a.ipynb" name="Cell 0"><failure/></testcase>'
        '<testcase classname="notebooks.a.ipynb" name="Cell 1"/>'
        '<testcase classname="notebooks.b_c.ipynb" name="Cell 3"><failure/></testcase></testsuite></testsuites>')
    assert numeric_paths.moved_cells(tmp_path / "j.xml") == {"a.ipynb": 1, "b_c.ipynb": 1}


FLOAT32_WORK = ("import torch; g = torch.Generator().manual_seed(0); a = torch.randn(256, 163, generator=g); "
                "w = torch.randn(163, 64, generator=g); "
                "print(repr([(a @ w).tanh().sum(0).tolist(), torch.log_softmax(a, 1).sum(0).tolist()]))")
NUMPY_TARGETS = ("from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__; "
                 "print(' '.join(t for t in __cpu_dispatch__ if __cpu_features__[t]))")


def in_path(path: str, code: str) -> str:
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                          env=numeric_paths.environment(path)).stdout


@pytest.mark.parametrize("path", [p for p in numeric_paths.paths() if p != "default"])
def test_each_numeric_path_moves_the_digits_of_float32_work(path):
    """A path under which the loop's kind of float32 work (a product, tanh, sums, log-softmax)
    comes out as on the default one would make its runs a repeat, not a test; and numpy must
    really run without the SIMD targets the path turns off."""
    if path == "avx2" and in_path("default", "import torch; print(torch.backends.cpu.get_cpu_capability())") != "AVX512\n":
        pytest.skip("this CPU's own kernels are AVX2 ones: the avx2 path is its default")
    assert in_path("default", FLOAT32_WORK) != in_path(path, FLOAT32_WORK)
    off = numeric_paths.paths()[path]["NPY_DISABLE_CPU_FEATURES"].split()
    assert not set(off) & set(in_path(path, NUMPY_TARGETS).split())
    if path == "scalar":
        assert in_path(path, NUMPY_TARGETS).split() == []


def test_a_path_sets_its_variables_and_clears_the_others(monkeypatch):
    monkeypatch.setenv("MKL_CBWR", "COMPATIBLE")
    monkeypatch.setenv("ATEN_CPU_CAPABILITY", "avx2")
    assert "MKL_CBWR" not in numeric_paths.environment("default")
    env = numeric_paths.environment("avx2")
    assert env["ATEN_CPU_CAPABILITY"] == "avx2" and "MKL_CBWR" not in env and env["PATH"] == os.environ["PATH"]


def typed_budget_errors(notebook: Path) -> list[str]:
    """The seed counts and budget shares that the markdown of an empirical notebook states and
    the data contradict: "N seeds" where no curve of its figures has N seeds on disk (nor is N
    the paper's count), and "X% of HARL's YM" that is no env's share of a figure's steps."""
    import re

    from oapo_lite.study.runs import experiments

    figs = [f for f in figures.GRID if f.notebook == notebook.stem]
    seeds, shares = set(), set()
    for fig in figs:
        for budget in ("cpu", "paper20"):
            if fig.runs_at is not None and budget not in fig.runs_at:
                continue
            df = experiments.read_figure(fig.id, budget, skip_missing=True)[0]
            if len(df):
                seeds |= set(df.groupby(["env", "label"] if "env" in df else ["label"])["seed"].nunique())
            for env in fig.envs(budget) or [None]:
                seeds.add(len(fig.budget("paper", env).seeds))  # the paper's own count
                steps, paper = fig.budget(budget, env).steps, fig.budget("paper", env).steps
                shares.add((f"{100 * steps / paper:.2g}", f"{paper / 1e6:g}"))
    errors = []
    for cell in nbformat.read(notebook, as_version=4).cells:
        if cell.cell_type != "markdown":
            continue
        errors += [f"{m.group(0)} (on disk: {sorted(seeds)})" for m in re.finditer(r"\b(\d+) seeds\b", cell.source)
                   if int(m.group(1)) not in seeds]
        errors += [f"{m.group(0)} (the figures' shares: {sorted(shares)})"
                   for m in re.finditer(r"\b(\d+(?:\.\d+)?)% of (?:HARL's )?(\d+(?:\.\d+)?)M\b", cell.source)
                   if (f"{float(m.group(1)):.2g}", f"{float(m.group(2)):g}") not in shares]
    return errors


@pytest.mark.parametrize("notebook", sorted({f.notebook for f in figures.GRID if f.notebook}))
def test_no_empirical_notebook_types_a_seed_count_or_share_that_the_data_contradict(notebook):
    assert typed_budget_errors(NOTEBOOKS[0].parent / f"{notebook}.ipynb") == []


def test_a_typed_seed_count_the_data_contradict_is_found(tmp_path):
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_markdown_cell("trained with 7 seeds, 3% of HARL's 25M steps")])
    path = tmp_path / "22_grf_fig6b.ipynb"
    nbformat.write(nb, path)
    assert [e.split(" (")[0] for e in typed_budget_errors(path)] == ["7 seeds", "3% of HARL's 25M"]


@pytest.mark.parametrize("path", [p for p in NOTEBOOKS if int(p.name[:2]) >= 10], ids=lambda p: p.stem)
def test_every_empirical_notebook_has_an_exercise(path):
    """CI runs every notebook at ``smoke``, so each exercise's solution runs there too."""
    cells = nbformat.read(path, as_version=4).cells
    assert any(c.cell_type == "markdown" and c.source.startswith("**Exercise") for c in cells)


def test_every_exercise_keeps_its_answer_folded_until_unfolded():
    """An exercise's prompt states no answer, and its solution (the next code cell) is folded,
    code and output, in JupyterLab (``jupyter`` metadata) and in the book (``hide-cell``)."""
    found = 0
    for path in NOTEBOOKS:
        cells = nbformat.read(path, as_version=4).cells
        for i, cell in enumerate(cells):
            if cell.cell_type != "markdown" or not cell.source.startswith("**Exercise"):
                continue
            found += 1
            assert "Expect" not in cell.source, (path.name, i)
            solution = next(c for c in cells[i + 1:] if c.cell_type == "code")
            assert solution.source.startswith("# Solution"), (path.name, i)
            assert solution.metadata.get("jupyter") == {"source_hidden": True, "outputs_hidden": True}, (path.name, i)
            assert "hide-cell" in solution.metadata.get("tags", []), (path.name, i)
    assert found >= 15


# What notebook 05 rebuilds Algorithm 1 from: the learner's internals it imports, each with the
# signature it calls. A change to one of them is a change to the notebook too: make both, then
# this table.
NOTEBOOK_05_USES = {
    "oapo_lite.neural.ppo_family": {
        "LearnerBatch": "(net: 'int', rows: 'list[int]', own: 'list[int]', w: 'torch.Tensor', act: 'torch.Tensor', "
                        "logp_old: 'torch.Tensor', kl_w: 'torch.Tensor', active: 'torch.Tensor | None' = None, "
                        "distinct: 'tuple[torch.Tensor, torch.Tensor] | None' = None) -> None",
        "advantages": "(critic: 'Critic', value_norm: 'ValueNorm', batch: 'Rollout', cfg: 'TrainConfig', bootstrap: 'bool')",
        "learner_dists": "(actors: 'Actors', inputs: 'Inputs', src: 'LearnerBatch', idx=slice(None, None, None)) "
                         "-> 'torch.Tensor'",
        "policy_distances": "(actors: 'Actors', inputs: 'Inputs', owner: 'list[int]', kl_reduce: 'str', "
                            "active: 'torch.Tensor | None' = None) -> 'np.ndarray'",
        "ppo_update": "(actors: 'Actors', opt: 'torch.optim.Optimizer', inputs: 'Inputs', src: 'LearnerBatch', "
                      "factor: 'torch.Tensor', adv: 'torch.Tensor', cfg: 'TrainConfig', rng: 'np.random.Generator') "
                      "-> 'float'",
        "trpo_update": "(actors: 'Actors', inputs: 'Inputs', src: 'LearnerBatch', factor: 'torch.Tensor', "
                       "adv: 'torch.Tensor', cfg: 'TrainConfig') -> 'tuple[float, float]'",
        "update_actors": "(actors: 'Actors', opts: 'list', batch: 'Rollout', units: 'list', order, adv: 'torch.Tensor', "
                         "spec: 'AlgoSpec', cfg: 'TrainConfig', rng: 'np.random.Generator')",
        "update_units": "(W: 'np.ndarray', owner: 'list[int]', by: 'str') -> 'list[tuple[int, np.ndarray, list[int]]]'",
    },
    "oapo_lite.neural.losses": {
        "off_agent_objective": "(logp_new: 'torch.Tensor', logp_old: 'torch.Tensor', weights: 'torch.Tensor', "
                               "factor: 'torch.Tensor', adv: 'torch.Tensor', clip: 'float | None', "
                               "active: 'torch.Tensor | None' = None) -> 'torch.Tensor'",
        "update_factor": "(factor: 'torch.Tensor', logp_new_own: 'torch.Tensor', logp_old_own: 'torch.Tensor', "
                         "active_own: 'torch.Tensor | None' = None) -> 'torch.Tensor'",
    },
}


def test_notebook_05_uses_the_learner_internals_pinned_here_with_their_signatures():
    import ast
    import importlib
    import inspect

    notebook = next(p for p in NOTEBOOKS if p.name.startswith("05_"))
    code = "\n".join(c.source for c in nbformat.read(notebook, as_version=4).cells if c.cell_type == "code")
    imported = {}
    for node in ast.walk(ast.parse(code)):
        if isinstance(node, ast.ImportFrom) and node.module in NOTEBOOK_05_USES:
            imported.setdefault(node.module, set()).update(a.name for a in node.names)
    assert imported == {m: set(names) for m, names in NOTEBOOK_05_USES.items()}
    for module, names in NOTEBOOK_05_USES.items():
        for name, signature in names.items():
            assert str(inspect.signature(getattr(importlib.import_module(module), name))) == signature, (module, name)


def test_the_overviews_package_table_names_every_module():
    """Notebook 00's table of the package lists every module and subpackage that exists, so a
    moved or new module cannot leave it stale."""
    import re

    import oapo_lite

    overview = next(p for p in NOTEBOOKS if p.name == "00_overview.ipynb")
    text = "".join(nbformat.read(overview, as_version=4).cells[0].source)
    named = {part.removesuffix(".py") for t in re.findall(r"`([^`]+)`", text[text.index("| layer | module |"):])
             for part in t.strip("/").split("/")}
    root = Path(oapo_lite.__file__).parent
    modules = {p.stem for p in root.rglob("*.py") if p.stem not in ("__init__", "__main__")}
    packages = {p.parent.name for p in root.rglob("*/__init__.py")}
    assert sorted((modules | packages) - named) == []
