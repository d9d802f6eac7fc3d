"""Tests of :mod:`delayed_rl.parallel.progress`: tqdm's bar, the lines without it, nothing when off.

Most tests put a recording stand-in for ``tqdm.auto`` in ``sys.modules`` (or ``None``, what a
missing tqdm looks like), so what :class:`RunProgress` asks of the bar is checked call by call.
"""

from __future__ import annotations

import sys
import types

import pytest

from delayed_rl.parallel.progress import RunProgress, tqdm_installed


class RecordingBar:
    """A stand-in for ``tqdm.auto.tqdm``: keeps its arguments and the calls made on it, in order."""

    def __init__(self, bars: list, **kwargs):
        self.kwargs, self.calls = kwargs, []
        bars.append(self)

    def update(self):
        self.calls.append("update")

    def clear(self):
        self.calls.append("clear")

    def refresh(self):
        self.calls.append("refresh")

    def close(self):
        self.calls.append("close")


@pytest.fixture
def bars(monkeypatch) -> list[RecordingBar]:
    """The bars made while the test runs, with ``tqdm.auto`` replaced by :class:`RecordingBar`."""
    made: list[RecordingBar] = []
    module = types.ModuleType("tqdm.auto")
    module.tqdm = lambda **kwargs: RecordingBar(made, **kwargs)
    monkeypatch.setitem(sys.modules, "tqdm.auto", module)
    return made


@pytest.fixture
def no_tqdm(monkeypatch) -> None:
    """As if tqdm were not installed."""
    monkeypatch.setitem(sys.modules, "tqdm.auto", None)


def test_tqdm_installed_says_whether_tqdm_auto_imports(monkeypatch, bars):
    assert tqdm_installed() is True
    monkeypatch.setitem(sys.modules, "tqdm.auto", None)
    assert tqdm_installed() is False


def test_the_bar_counts_the_runs_on_stderr_and_is_closed_once(bars, capsys):
    with RunProgress(5, "delay-sweep", enabled=True) as progress:
        progress.tick()
        progress.tick()
        assert progress.done == 2
        (bar,) = bars
        assert bar.kwargs == {"total": 5, "desc": "delay-sweep", "unit": "run", "file": sys.stderr}
        assert bar.calls == ["update", "update"]
    progress.__exit__(None, None, None)  # a second exit does not close the bar again
    assert bar.calls == ["update", "update", "close"]
    assert capsys.readouterr() == ("", "")  # the bar does the drawing, no lines besides


def test_paused_clears_the_bar_and_draws_it_again_even_when_the_body_raises(bars):
    with RunProgress(2, "sweep", enabled=True) as progress:
        (bar,) = bars
        with progress.paused():
            assert bar.calls == ["clear"]
        assert bar.calls == ["clear", "refresh"]
        with pytest.raises(RuntimeError, match="in the body"), progress.paused():
            raise RuntimeError("in the body")
        assert bar.calls == ["clear", "refresh", "clear", "refresh"]


def test_without_tqdm_each_tick_prints_a_line_on_stderr(no_tqdm, capsys):
    with RunProgress(3, "sweep", enabled=True) as progress:
        for _ in range(3):
            progress.tick()
        with progress.paused():
            print("a table")
    out, err = capsys.readouterr()
    assert err.splitlines() == [f"[sweep] {done}/3 runs done" for done in (1, 2, 3)]
    assert out == "a table\n"
    assert progress.done == 3


@pytest.mark.parametrize("tqdm", ["installed", "missing"])
def test_disabled_progress_counts_the_runs_but_shows_nothing(tqdm, monkeypatch, bars, capsys):
    if tqdm == "missing":
        monkeypatch.setitem(sys.modules, "tqdm.auto", None)
    with RunProgress(4, "sweep", enabled=False) as progress:
        progress.tick()
        progress.tick()
        with progress.paused():
            pass
    assert progress.done == 2
    assert bars == []  # no bar made, even with tqdm there
    assert capsys.readouterr() == ("", "")


def test_tqdms_own_bar_ends_drawn_complete_on_stderr(capsys):
    assert tqdm_installed()  # tqdm is in the dev extra
    with RunProgress(2, "delay-sweep", enabled=True) as progress:
        progress.tick()
        progress.tick()
    out, err = capsys.readouterr()
    assert out == ""
    assert "delay-sweep: 100%" in err and "| 2/2 [" in err
