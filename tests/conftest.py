"""Every test starts on the repository's own figures/ folder, whatever ``OAPO_FIGURES`` says in
the shell that runs the suite: the tests of the committed runs read them there, and a test that
wants another folder sets the variable itself."""
import pytest


@pytest.fixture(autouse=True)
def committed_figures(monkeypatch):
    monkeypatch.delenv("OAPO_FIGURES", raising=False)
