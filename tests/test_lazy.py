"""``delayed_rl._lazy``: a package's names imported on first use, a missing extra named."""

from __future__ import annotations

import sys

import pytest

from delayed_rl._lazy import lazy_attributes


@pytest.fixture
def package(tmp_path, monkeypatch):
    """A package ``lazypkg`` with a module that imports ``needed_pkg`` and one that breaks."""
    root = tmp_path / "lazypkg"
    root.mkdir()
    (root / "__init__.py").write_text("")
    (root / "light.py").write_text("VALUE = 7\n")
    (root / "heavy.py").write_text("import needed_pkg\nHEAVY = 1\n")
    (root / "broken.py").write_text("import some_unrelated_missing_module\nBROKEN = 1\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setitem(sys.modules, "needed_pkg", None)  # what a missing package looks like
    yield lazy_attributes(
        "lazypkg",
        {"VALUE": "light", "HEAVY": "heavy", "BROKEN": "broken"},
        ("needed_pkg",),
        "Needed",
        "needy",
        '`pip install "x[needy]"`',
    )
    for name in [m for m in sys.modules if m.startswith("lazypkg")]:
        del sys.modules[name]


def test_a_name_is_imported_from_its_module_on_first_use(package):
    assert "lazypkg.light" not in sys.modules
    assert package("VALUE") == 7
    assert "lazypkg.light" in sys.modules


def test_an_unknown_name_is_an_attribute_error(package):
    with pytest.raises(AttributeError, match="module 'lazypkg' has no attribute 'NOPE'"):
        package("NOPE")


def test_a_missing_extra_is_named_with_its_install_command(package):
    with pytest.raises(
        ImportError,
        match=r"lazypkg\.HEAVY needs Needed, which is not installed \(needed_pkg is missing\): "
        r"install the needy extra, `pip install \"x\[needy\]\"`",
    ):
        package("HEAVY")


def test_any_other_import_error_passes_through_unchanged(package):
    with pytest.raises(ImportError) as caught:
        package("BROKEN")
    assert caught.value.name == "some_unrelated_missing_module"
    assert "extra" not in str(caught.value)
