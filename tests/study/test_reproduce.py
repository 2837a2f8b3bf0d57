"""Executing notebooks: the kernel says nothing on the terminal when all is well, and a failing
cell is reported with its notebook and its cell."""
import nbformat
import pytest

from oapo_lite.study.catalogue import figures
from oapo_lite.study.runs import reproduce
from oapo_lite.study.runs.reproduce import NotebookFailed, run_notebook


def _notebook(tmp_path, name: str, *sources: str):
    path = tmp_path / name
    nbformat.write(nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell(s) for s in sources]), path)
    return path


def test_a_good_notebook_runs_without_kernel_messages_on_the_terminal(tmp_path, capfd):
    path = _notebook(tmp_path, "good.ipynb", "x = 2", "print(x + 1)")
    run_notebook(path, tmp_path / "out.ipynb", {}, cwd=tmp_path)
    out, err = capfd.readouterr()  # file-descriptor level: the kernel process writes here too
    assert "IPKernelApp" not in out + err and "KeyboardInterrupt" not in out + err
    assert nbformat.read(tmp_path / "out.ipynb", 4).cells[1].outputs[0]["text"] == "3\n"


def test_a_failing_cell_is_reported_with_its_notebook_and_cell(tmp_path):
    path = _notebook(tmp_path, "bad.ipynb", "x = 2", "raise ValueError(f'broken at {x}')", "print('never')")
    with pytest.raises(NotebookFailed) as err:
        run_notebook(path, tmp_path / "out.ipynb", {}, cwd=tmp_path)
    message = str(err.value)
    assert message.startswith("bad.ipynb failed in cell 2 (In [2]) with ValueError: broken at 2")
    assert str(tmp_path / "out.ipynb") in message


def test_notebooks_run_side_by_side_each_in_its_own_kernel(tmp_path, capfd):
    """Two notebooks at once (as ``reproduce`` runs them): each kernel must get only its own
    messages; with jupyter_client's default IPC paths they shared sockets."""
    from concurrent.futures import ThreadPoolExecutor

    paths = [_notebook(tmp_path, f"nb{k}.ipynb", "import os", f"print({k}, os.getpid())") for k in range(2)]
    with ThreadPoolExecutor(2) as pool:
        list(pool.map(lambda p: run_notebook(p, tmp_path / f"out_{p.name}", {}, cwd=tmp_path), paths))
    pids = set()
    for k, path in enumerate(paths):
        text = nbformat.read(tmp_path / f"out_{path.name}", 4).cells[1].outputs[0]["text"]
        assert text.split()[0] == str(k)
        pids.add(text.split()[1])
    assert len(pids) == 2
    out, err = capfd.readouterr()
    assert "IPKernelApp" not in out + err


def test_the_student_budget_trains_and_runs_only_what_it_shows():
    """Fig. 3b-3d at 3 seeds: the MAPPO and lambda traps; the other figures train nothing there,
    and only the notebooks that need no other runs are executed."""
    assert {r.figure for f in figures.FIGURES for r in figures.runs_of(f, "student")} == {"fig3b", "fig3c", "fig3d"}
    assert len(figures.runs_of("fig3b", "student")) == 5 * 3  # OAPPO, OATRPO, MAPPO, HAPPO, HATRPO
    names = [p.name.split("_")[0] for p in reproduce.notebook_paths("student")]
    assert names == ["00", "01", "02", "03", "04", "05", "10", "11", "12"]
    assert len(reproduce.notebook_paths()) > len(names)  # every other budget runs all of them
