"""rsart.console.guarded: the one way every console script of the family (rsart, rsart-eval, pd2gs,
rsart-leaderboard) ends -- exit codes and one-line messages, no traceback unless RSART_DEBUG asks."""
import pytest

from rsart.console import guarded
from rsart.errors import RsartError

pytestmark = pytest.mark.core


def test_exit_codes_and_one_line_messages(capsys, monkeypatch):
    monkeypatch.delenv("RSART_DEBUG", raising=False)
    assert guarded(lambda: None) == 0
    assert guarded(lambda: 3) == 3

    def bad_input():
        raise RsartError("meta.json: joints[0].axis: zero-length vector")
    assert guarded(bad_input, "pd2gs") == 2
    assert capsys.readouterr().err == "pd2gs: error: meta.json: joints[0].axis: zero-length vector\n"

    def missing_extra():
        raise ModuleNotFoundError("No module named 'pxr'", name="pxr")
    assert guarded(missing_extra) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "pip install" in err and "usd" in err

    def bug():
        raise ZeroDivisionError("a name with a\nnew line")
    assert guarded(bug, "rsart-eval") == 1
    err = capsys.readouterr().err
    # one line, naming the exception, with the control character escaped
    assert err.count("\n") == 1 and "internal error" in err and "ZeroDivisionError: a name with a\\nnew line" in err

    def interrupt():
        raise KeyboardInterrupt
    assert guarded(interrupt, "pd2gs", "interrupted (finished work is kept)") == 130
    assert capsys.readouterr().err == "pd2gs: interrupted (finished work is kept)\n"


def test_rsart_debug_re_raises_a_bug(monkeypatch):
    monkeypatch.setenv("RSART_DEBUG", "1")

    def bug():
        raise ZeroDivisionError("boom")
    with pytest.raises(ZeroDivisionError):
        guarded(bug)


def test_an_import_error_of_no_extra_is_a_bug_not_a_missing_extra(capsys, monkeypatch):
    monkeypatch.delenv("RSART_DEBUG", raising=False)

    def bug():
        raise ModuleNotFoundError("No module named 'not_an_extra_module'", name="not_an_extra_module")
    assert guarded(bug) == 1
    assert "internal error" in capsys.readouterr().err
