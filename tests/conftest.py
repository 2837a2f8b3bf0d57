"""Every test starts on the repository's own figures/ folder, whatever ``OAPO_FIGURES`` says in
the shell that runs the suite: the tests of the committed runs read them there, and a test that
wants another folder sets the variable itself.

Every test module also says whether its outcome can depend on the floating-point kernels
(``NUMERIC``: training, closed forms met to a tolerance, statistics of float data) or not
(``NOT_NUMERIC``: errors, files, processes, parsing, integer oracles): ``tests/numeric_paths.py``
runs only the first kind again under its other kernels (``pytest -m numeric``)."""
import sys
from pathlib import Path

import pytest

# the suite's helpers (fakes.py, numeric_paths.py) for the test modules in the layers' folders
sys.path.insert(0, str(Path(__file__).resolve().parent))

NUMERIC = {"test_adaptive", "test_assumptions", "test_claims", "test_divergence", "test_envs", "test_exact", "test_gate_study",
           "test_layout_study", "test_losses", "test_mamujoco", "test_normalize", "test_reuse", "test_rollout", "test_seac_seps",
           "test_smax", "test_statistics", "test_tabular", "test_train", "test_trpo", "test_verdicts"}
NOT_NUMERIC = {"test_bad_cli", "test_bad_maps", "test_bad_runs", "test_bad_study_input", "test_book",
               "test_checkpoint_data", "test_costs", "test_experiments", "test_grf", "test_interactive",
               "test_layers", "test_layouts", "test_maps", "test_notebooks", "test_plotting", "test_protocols",
               "test_ray_executor", "test_render", "test_reproduce", "test_selection"}


def pytest_collection_modifyitems(config, items):
    for item in items:
        module = item.module.__name__.rsplit(".", 1)[-1]
        if module in NUMERIC:
            item.add_marker(pytest.mark.numeric)
        elif module not in NOT_NUMERIC:
            raise pytest.UsageError(f"{item.path}: say in tests/conftest.py whether its outcome can depend on "
                                    "the floating-point kernels (NUMERIC) or not (NOT_NUMERIC)")


@pytest.fixture(autouse=True)
def committed_figures(monkeypatch):
    monkeypatch.delenv("OAPO_FIGURES", raising=False)
