"""The haptic-anfis command: train, evaluate, errors."""
import json

import pytest

from haptic_anfis.cli import main
from haptic_anfis.tissue.dataset import save_dataset


@pytest.fixture
def dataset_csv(synthetic, tmp_path):
    return str(save_dataset(synthetic, tmp_path / 'forces.csv'))


def test_train_then_evaluate(dataset_csv, tmp_path, capsys):
    out = tmp_path / 'model.json'
    rc = main(['train', dataset_csv, '--out', str(out), '--structure', '2-2-2', '--epochs', '5'])
    assert rc == 0
    text = capsys.readouterr().out
    assert 'Fx' in text and 'test N' in text and 'wrote' in text
    doc = json.loads(out.read_text())
    assert [o['structure'] for o in doc['outputs']] == [[2, 2, 2]] * 3
    assert main(['evaluate', str(out), dataset_csv]) == 0
    text = capsys.readouterr().out
    assert 'RMSE N' in text and 'the dataset the model was trained on' in text


def test_train_prints_every_candidate_of_the_search(dataset_csv, tmp_path, capsys):
    cfg = tmp_path / 'cfg.yaml'
    cfg.write_text('force_model:\n  structure: null\n  search_epochs: 3\n  epochs: 5\n'
                   '  max_mfs: [3, 2, 2]\n')
    assert main(['train', dataset_csv, '--out', str(tmp_path / 'm.json'), '--config', str(cfg)]) == 0
    text = capsys.readouterr().out
    assert text.count('structure search (2 candidates)') == 3
    assert '<- chosen' in text


def test_config_with_unknown_key_is_rejected(dataset_csv, tmp_path, capsys):
    cfg = tmp_path / 'cfg.yaml'
    cfg.write_text('force_model:\n  epochz: 3\n')
    assert main(['train', dataset_csv, '--out', str(tmp_path / 'm.json'), '--config', str(cfg)]) == 1
    assert "unknown force_model key(s) ['epochz']" in capsys.readouterr().err


def test_a_config_without_its_section_or_with_a_bad_epoch_count_is_one_line(dataset_csv,
                                                                          tmp_path, capsys):
    """A typo in the section name (or another config file) trained with every default and said
    nothing; an epoch count as text was a traceback deep in training."""
    cfg = tmp_path / 'cfg.yaml'
    out = tmp_path / 'm.json'
    for text, what in (('force-model: {epochs: 5}\n', 'no "force_model" section (its top-level '
                                                       'keys: force-model)'),
                       ('force_model: {epochs: 4e1}\n', "epochs: expected an integer >= 1, got "
                                                         "'4e1'"),
                       ('force_model: {search_epochs: 0}\n', 'search_epochs: expected an '
                                                              'integer >= 1, got 0')):
        cfg.write_text(text)
        assert main(['train', dataset_csv, '--out', str(out), '--config', str(cfg)]) == 1
        err = capsys.readouterr().err
        assert what in err and len(err.strip().splitlines()) == 1, err
    assert not out.exists()
    with pytest.raises(SystemExit):   # argparse: exit 2 with its usage line
        main(['train', dataset_csv, '--out', str(out), '--epochs', '-3'])
    assert "'-3': expected an integer >= 1" in capsys.readouterr().err


def test_a_dataset_in_millimetres_or_with_a_zero_depth_is_refused_before_training(
        synthetic, tmp_path, capsys):
    """Training wrote a model from a dataset in millimetres that loading then refused (it
    could replace a good model); a depth of 0 was named by its index in the training split."""
    import numpy as np

    from haptic_anfis.tissue.dataset import ForceDataset
    out = tmp_path / 'm.json'
    mm = save_dataset(ForceDataset(synthetic.X * 1000, synthetic.Y, synthetic.point),
                      tmp_path / 'mm.csv')
    assert main(['train', str(mm), '--out', str(out), '--epochs', '2']) == 1
    err = capsys.readouterr().err
    assert 'mm.csv' in err and 'expected metres within ±1 m' in err and not out.exists()
    X = synthetic.X.copy()
    X[7, 3] = 0.0
    zero = save_dataset(ForceDataset(X, synthetic.Y, synthetic.point), tmp_path / 'zero.csv')
    assert main(['train', str(zero), '--out', str(out), '--epochs', '2']) == 1
    err = capsys.readouterr().err
    assert 'zero.csv' in err and 'depth_m = 0 at row 8' in err and not out.exists()
    assert np.all(synthetic.X[:, 3] > 0)


def test_shipped_config_is_valid():
    from pathlib import Path

    from haptic_anfis.commands.train import load_config
    params = load_config(str(Path(__file__).resolve().parents[2] / 'config' / 'force_model.yaml'))
    # the default the force server loads: depth-scaled over (y, z, depth), y/z band 15 %
    assert params['form'] == 'depth_scaled' and params['inputs'] == 'auto'   # x checked
    assert params['extrapolation'] == (0.0, 0.15, 0.15, 0.0)


def test_bad_inputs_give_one_line_errors(tmp_path, capsys):
    assert main(['train', str(tmp_path / 'missing.csv'), '--out', str(tmp_path / 'm.json')]) == 1
    assert 'does not exist' in capsys.readouterr().err
    bad = tmp_path / 'bad.json'
    bad.write_text('{}')
    assert main(['evaluate', str(bad), str(tmp_path / 'x.csv')]) == 1
    assert 'not a haptic_anfis force-model file' in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(['train', 'x.csv', '--out', 'm.json', '--structure', '3-3-3-3-3'])


def test_no_command_prints_help(capsys):
    assert main([]) == 2
    assert 'train' in capsys.readouterr().out


def test_bench_model_takes_per_output_structures(dataset_csv, tmp_path, capsys):
    cfg = tmp_path / 'cfg.yaml'
    cfg.write_text('force_model:\n  epochs: 3\n  structure: [3, 2, 2]\n')
    assert main(['bench', 'model', '--dataset', dataset_csv, '--config', str(cfg), '--repeats', '50',
                 '--structures', 'config', '2-2-2/3-2-2/2-3-2']) == 0
    text = capsys.readouterr().out
    assert '3-2-2/3-2-2/3-2-2' in text          # 'config' = the config's structure
    assert '2-2-2/3-2-2/2-3-2' in text          # one structure per output (Fx/Fy/Fz)
    with pytest.raises(SystemExit):
        main(['bench', 'model', '--structures', '2-2-2/2-2-2'])


def _parsers(parser, path=()):
    """Every (command path, parser) of the command tree under ``parser``."""
    import argparse
    yield path, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _parsers(sub, (*path, name))


def test_every_commands_help_prints():
    """--help of every command and subcommand formats (a bare % in a help string made
    argparse raise a TypeError for ``launch --help``)."""
    from haptic_anfis.cli import build_parser
    found = list(_parsers(build_parser()))
    assert len(found) > 20
    for path, parser in found:
        text = parser.format_help()
        assert 'usage:' in text, path


def test_the_command_table_lists_every_command_module_and_no_other():
    import pkgutil

    from haptic_anfis import commands
    from haptic_anfis.cli import command_module
    modules = {m.name for m in pkgutil.iter_modules(commands.__path__) if not m.name.startswith('_')}
    assert set(commands.COMMANDS) == modules
    for word in commands.COMMANDS:
        assert command_module(word).NAME == word


def test_help_imports_no_command_module_nor_ros_numba_or_the_fe_stack():
    """``haptic-anfis --help`` lists the commands from the table alone; a command's --help
    imports that command's module only."""
    import subprocess
    import sys
    code = ('import sys, contextlib, io\n'
            'from haptic_anfis.cli import main\n'
            'with contextlib.redirect_stdout(io.StringIO()) as out, contextlib.suppress(SystemExit):\n'
            '    main(sys.argv[1:])\n'
            'assert "usage:" in out.getvalue()\n'
            'print(sorted(m for m in sys.modules if m.startswith("haptic_anfis.commands.") or '
            'm.split(".")[0] in ("rclpy", "numba", "felupe", "matplotlib", "trimesh")))\n')
    r = subprocess.run([sys.executable, '-c', code, '--help'], capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0 and r.stdout.strip() == '[]', r.stdout + r.stderr
    r = subprocess.run([sys.executable, '-c', code, 'trainees', '--help'], capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert [m for m in eval(r.stdout) if m.startswith('haptic_anfis.commands.')] == \
        ['haptic_anfis.commands.trainees'], r.stdout


def test_without_ros_a_ros_command_is_one_line_and_the_bag_commands_still_load(tmp_path):
    """rclpy comes with ROS 2 (or the 'ros' extra): ``topic`` says in one line that it is
    missing; ``bag info`` (the bag room reads bags without ROS) runs and reports the bad path."""
    import subprocess
    import sys
    code = ('import sys; sys.modules["rclpy"] = None\n'
            'from haptic_anfis.cli import main\n'
            'sys.exit(main(sys.argv[1:]))\n')

    def run(*argv):
        return subprocess.run([sys.executable, '-c', code, *argv], capture_output=True,
                              text=True, timeout=120)
    r = run('topic', 'list')
    assert r.returncode == 1 and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert r.stderr.startswith('haptic-anfis topic: error: ') and 'rclpy' in r.stderr
    r = run('bag', 'info', str(tmp_path / 'no_bag'))
    assert r.returncode == 1 and 'rclpy' not in r.stderr, r.stderr
    assert str(tmp_path / 'no_bag') in r.stderr
    r = run('bag', 'play', str(tmp_path / 'no_bag'))
    assert r.returncode == 1 and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert r.stderr.startswith('haptic-anfis bag: error: needs rclpy'), r.stderr
