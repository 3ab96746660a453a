"""One's own cases in a user folder every command sees; ``cases list`` in 100 columns."""
from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from haptic_anfis.cases import CASE_DIR_ENV, CaseError, CaseLibrary, library, user_case_dir
from haptic_anfis.cli import main
from haptic_anfis.tissue.scene import SCENE_DIR


def own_scene(folder: Path, name: str = 'my_case') -> Path:
    """The default scene copied as the user's case ``name``."""
    doc = yaml.safe_load((SCENE_DIR / 'default.yaml').read_text())
    doc.update(name=name, description=f'{name}: my own lesion, ' + 'long words ' * 12)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f'{name}.yaml'
    path.write_text(yaml.safe_dump(doc))
    return path


@pytest.fixture
def env(monkeypatch, tmp_path):
    """No case folder from the caller's environment (restored afterwards)."""
    monkeypatch.delenv(CASE_DIR_ENV, raising=False)
    monkeypatch.setenv('XDG_DATA_HOME', str(tmp_path / 'xdg'))
    return monkeypatch


def test_the_user_folder_defaults_to_xdg_and_follows_the_variable(env, tmp_path):
    assert user_case_dir() == tmp_path / 'xdg' / 'haptic_anfis' / 'cases'
    env.setenv(CASE_DIR_ENV, str(tmp_path / 'mine'))
    assert user_case_dir() == tmp_path / 'mine'


def test_own_cases_join_the_library_and_never_shadow_a_package_case(env, tmp_path):
    folder = user_case_dir()
    own_scene(folder)
    own_scene(folder, 'normal')   # a package case's name: the package's wins
    lib = library()
    assert lib.names()[-1] == 'my_case' and lib.names().count('normal') == 1
    assert lib.shadowed() == ['normal'] and lib.user_names() == ['my_case']
    c = lib.get('my_case')
    assert c.scene_path == folder / 'my_case.yaml'
    assert c.model_path == folder / 'cases' / 'my_case' / 'model.json'
    assert c.mesh_path.name == 'default_surface.stl' and c.mesh_path.is_file()
    assert lib.get('normal').scene_path.parent == SCENE_DIR.resolve()
    with pytest.raises(CaseError, match='cases generate my_case'):
        c.require()
    with pytest.raises(CaseError, match=f'own cases are read from {str(folder)!r}'):
        lib.get('nobody')
    assert 'my_case' not in [x.name for x in lib.ready()]   # no model yet: never drawn
    assert CaseLibrary().names() == CaseLibrary(user_dir=tmp_path / 'none').names()


def test_case_dir_option_reaches_every_command_and_the_list_fits_100_columns(env, tmp_path,
                                                                             capsys):
    folder = tmp_path / 'by_option'
    own_scene(folder)
    assert main(['cases', 'list', '--case-dir', str(folder)]) == 0
    out = capsys.readouterr().out
    lines = out.splitlines()
    assert max(map(len, lines)) <= 100, max(lines, key=len)
    assert lines[0].split() == ['case', 'lvl', 'lumps', 'ready', 'description']
    mine = next(ln for ln in lines if ln.startswith('my_case*'))
    assert mine.split()[1:4] == ['-', '?/1', 'no'] and mine.endswith('...')
    assert any(ln.startswith('lib_free_m_dense') and 'No lesion' in ln for ln in lines)
    assert f'own cases: {folder}' in out
    # the option also reaches the commands that run a case (and the nodes they start)
    from haptic_anfis.cli import build_parser
    for argv in (['sim'], ['launch'], ['exam', 'run'], ['exam', 'report', 'B'], ['view', 'B'],
                 ['cases', 'generate'], ['cases', 'sweep']):
        assert build_parser().parse_args([*argv, '--case-dir', str(folder)]).case_dir == \
            str(folder)
    file = tmp_path / 'a_file'
    file.write_text('x')
    assert main(['cases', 'list', '--case-dir', str(file)]) == 1
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and 'expected a folder of scene files' in err


def test_wide_list_is_the_old_table(env, capsys):
    assert main(['cases', 'list', '--wide', '--no-timing']) == 0
    head = capsys.readouterr().out.splitlines()[0]
    assert 'structure Fx/Fy/Fz' in head and len(head) > 150
