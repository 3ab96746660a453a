"""The package's public surface (issue 28.4): py.typed, __all__ on every package, and one error
base class that the package's own errors derive from and the CLI catches once."""
from __future__ import annotations

import ast
import importlib
from pathlib import Path

from haptic_anfis.errors import HapticAnfisError

PKG = Path(__file__).resolve().parents[2] / 'haptic_anfis'


def test_py_typed_ships_and_every_package_declares_all():
    assert (PKG / 'py.typed').is_file()
    assert "'py.typed'" in (PKG.parent / 'setup.py').read_text()
    missing = [str(f.relative_to(PKG.parent)) for f in PKG.rglob('__init__.py')
               if '__all__' not in f.read_text()]
    assert missing == []


def _error_classes():
    """(module, class name) of every class named *Error / *Failed defined in the package."""
    for f in sorted(PKG.rglob('*.py')):
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, ast.ClassDef) and node.name.endswith(('Error', 'Failed')):
                mod = '.'.join(f.relative_to(PKG.parent).with_suffix('').parts)
                yield mod.removesuffix('.__init__'), node.name


def test_every_error_of_the_package_derives_from_the_one_base_class():
    classes = list(_error_classes())
    assert len(classes) >= 12
    for mod, name in classes:
        if mod.startswith(('haptic_anfis.nodes.', 'haptic_anfis.session.')):
            try:
                importlib.import_module('rclpy')
            except ImportError:  # node modules need rclpy to import
                continue
        cls = getattr(importlib.import_module(mod), name)
        assert issubclass(cls, HapticAnfisError), f'{mod}.{name}'


def test_the_cli_prints_a_package_error_as_one_line(monkeypatch, capsys):
    from haptic_anfis import cli
    from haptic_anfis.commands import evaluate

    def boom(args):
        raise HapticAnfisError('model.json: not a model file')
    monkeypatch.setattr(evaluate, 'run', boom)
    assert cli.main(['evaluate', 'model.json', 'data.csv']) == cli.EXIT_ERROR
    assert capsys.readouterr().err == 'haptic-anfis evaluate: error: model.json: not a model file\n'
