"""Executing notebooks: the kernel says nothing on the terminal when all is well, and a failing
cell is reported with its notebook and its cell."""
import nbformat
import pytest

from oapo_lite.reproduce import NotebookFailed, run_notebook


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
