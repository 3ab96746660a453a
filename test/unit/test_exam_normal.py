"""After the exam the breast's normal background is shown beside the lesions, and the report
splits the false marks into those on normal tissue and those elsewhere (exam specificity)."""
import numpy as np
import pytest

from haptic_anfis.cases import library
from haptic_anfis.contact import load_mesh
from haptic_anfis.exam.config import ExamConfig
from haptic_anfis.exam.lesions import subject_from_scene
from haptic_anfis.exam.session import ExamSession, Surface
from haptic_anfis.exam.normal import RIB_POINTS, normal_lines, skin_point, specificity_text
from haptic_anfis.tissue.scene import SCENE_DIR
from haptic_anfis.view.debrief import normal_markers, panel_numbers
from haptic_anfis.view.legend import legend_html
from haptic_anfis.view.panel import numbers_markdown

FREE = 'nod_s_fatty_free'                                # graded, ready, no lesion
RIBS = SCENE_DIR / 'nod_s_fatty_two_ribs.yaml'      # a scene file: ribs, not graded here


@pytest.fixture(scope='module')
def surface():
    mesh = load_mesh(library().get(FREE).mesh_path, unit='mm')   # the small breast's skin
    mesh.merge_vertices()
    return Surface.from_mesh(mesh)


def _report(surface, subject, marks):
    s = ExamSession(surface, subject, ExamConfig())
    for t, p in enumerate(marks):
        s.add_mark(float(t), p)
    return s.report()


def _skin(report, name):
    return np.array(next(e for e in report['normal'] if e['name'] == name)['surface_mm']) * 1e-3


def test_a_graded_nodular_case_reports_every_lobule_with_its_felt_bump(surface):
    case = library().get(FREE)
    subject = subject_from_scene(case.scene_path)
    bg = case.grading()['background']
    r0 = _report(surface, subject, [])
    normal = r0['normal']
    assert [e['name'] for e in normal] == [n.name for n in subject.background.nodules]
    for e, g, n in zip(normal, bg['nodules'], subject.background.nodules):
        assert e['kind'] == 'nodule' and e['what'] == 'a normal glandular lobule'
        assert e['bump_pct'] == pytest.approx(g['bump_pct'], abs=0.05)   # the FE grading's
        assert e['confounder'] == (g['name'] in bg['confounders'])
        assert e['depth_mm'] == pytest.approx(g['depth_m'] * 1e3, abs=0.5)   # skin over it
        assert e['surface_mm'][1:] == pytest.approx([c * 1e3 for c in n.centre[1:]], abs=0.01)
    # a mark on a lobule's skin and one on plain fat: both false, split by where they fell
    n = subject.background.nodules[5]
    ys = np.linspace(-0.03, 0.03, 31)
    margin = ExamConfig().hit_margin   # a mark this close to a lobule is on it
    yz = next((y, z) for y in ys for z in ys
              if subject.background.region_at(y, z, margin) is None)
    plain = skin_point(surface.detector, *yz)
    r = _report(surface, subject, [_skin(r0, n.name), plain])
    assert r['false_marks'] == 2 and r['false_marks_normal'] == 1
    assert r['false_marks_elsewhere'] == 1
    sp = r['specificity']
    assert (sp['on_normal'], sp['elsewhere'], sp['clean']) == (1, 1, False)
    assert sp['normal_regions'] == 30 and sp['threshold_pct'] == bg['threshold_pct']
    assert specificity_text(r) == ' (1 on normal tissue, 1 elsewhere)'
    assert next(e for e in r['normal'] if e['name'] == n.name)['marks'] == [0]
    assert (f'2 false mark(s): 1 on normal tissue, not a lesion: a normal glandular lobule '
            f'({n.name}); 1 elsewhere') in r['feedback']
    lines = normal_lines(r)
    lo, hi = bg['nodule_bump_pct']
    assert lines[0] == (f'normal background: 30 glandular lobules (bumps {lo:+.1f}..{hi:+.1f} % '
                        'at deep pressure)')
    assert lines[1].startswith(f"stand out as much as a lesion (bump >= {bg['threshold_pct']:g} %)")
    assert lines[-1].startswith(f'false mark 0 on {n.name}: a normal glandular lobule, bump')
    # the debrief's markers: every lobule drawn, labelled only when marked or standing out
    marks = normal_markers(r)
    assert len(marks) == 30 and {m.status for m in marks} <= {'normal', 'confounder'}
    labelled = [m.name for m in marks if m.label]
    assert n.name in labelled and all(m.marked or m.status == 'confounder'
                                      for m in marks if m.label)
    np.testing.assert_allclose(next(m for m in marks if m.name == n.name).surface,
                               _skin(r, n.name))
    assert '(1 on normal tissue)' in numbers_markdown(panel_numbers(r))
    assert 'normal lobule / rib' in legend_html(debrief=True, background=True)
    assert 'normal lobule' not in legend_html(debrief=True)
    # no false mark: a clean (specific) exam, nothing split
    assert r0['specificity']['clean'] and specificity_text(r0) == ''


def test_ribs_are_drawn_as_lines_across_the_region_and_an_ungraded_bump_is_unknown(surface):
    subject = subject_from_scene(RIBS)   # not a library case here: no grading, no bumps
    r = _report(surface, subject, [])
    ribs = [e for e in r['normal'] if e['kind'] == 'rib']
    assert [e['name'] for e in ribs] == [b.name for b in subject.background.ribs]
    inside = r['region_radius_mm'] * 1e-3
    for e, b in zip(ribs, subject.background.ribs):
        line = np.array(e['line_mm']).reshape(-1, 3)
        if abs(b.z) < inside:   # across the region to examine; none for a rib beyond it
            assert len(line) == RIB_POINTS and np.allclose(line[:, 2], b.z * 1e3, atol=0.01)
            assert np.abs(line[:, 1]).max() <= r['region_radius_mm'] + 0.01
        else:
            assert len(line) == 0
        assert e['what'] == 'a rib' and e['bump_pct'] is None and not e['confounder']
    assert sum(len(e['line_mm']) > 0 for e in ribs) == 2   # the ribs at z = -15 and 15 mm
    assert all(e['bump_pct'] is None for e in r['normal'])
    assert r['specificity']['threshold_pct'] is None
    assert normal_lines(r) == [f'normal background: {len(subject.background.nodules)} '
                               'glandular lobules, 2 ribs under the region']
    marks = normal_markers(r)   # the ribs beyond the region are not drawn
    assert [m.name for m in marks if m.kind == 'rib'] == [e['name'] for e in ribs
                                                          if e['line_mm']]
    assert all(m.label for m in marks if m.kind == 'rib')   # a rib is always named


def test_the_report_figure_draws_the_lobules_and_ribs_beside_the_lesions(surface, tmp_path,
                                                                        monkeypatch):
    import matplotlib.pyplot as plt
    from matplotlib.colors import to_hex
    from haptic_anfis import palette
    from haptic_anfis.exam.figure import save_figure
    figs = []
    monkeypatch.setattr(plt, 'close', figs.append)
    s = ExamSession(surface, subject_from_scene(RIBS), ExamConfig())
    r = s.report()
    save_figure(s, r, tmp_path / 'report.png')
    ax = figs[0].axes[1]
    blue = palette.NORMAL['normal']
    circles = [p for p in ax.patches if p.get_linestyle() == ':' and to_hex(p.get_edgecolor())
               == blue]
    lines = [ln for ln in ax.get_lines() if ln.get_linestyle() == ':' and len(ln.get_xdata()) > 1]
    assert len(circles) == sum(e['kind'] == 'nodule' for e in r['normal'])
    assert len(lines) == sum(bool(e['line_mm']) for e in r['normal'])
    assert 'normal lobule / rib' in [t.get_text() for t in ax.get_legend().get_texts()]
    assert (tmp_path / 'report.png').stat().st_size > 10_000


def test_a_smooth_case_has_no_background_to_show(surface):
    r = _report(surface, subject_from_scene(SCENE_DIR / 'lib_s_fatty_two.yaml'), [])
    assert r['normal'] == [] and normal_lines(r) == [] and normal_markers(r) == []
    assert r['specificity']['normal_regions'] == 0
    assert normal_markers({'lesions': []}) == []   # a report made before the background


def test_a_confounder_is_drawn_apart_and_named_with_its_bump():
    """No shipped ready case has a normal region that reaches the threshold yet: a report entry
    says what the debrief does with one."""
    def entry(name, bump, confounder, marks=()):
        return {'name': name, 'kind': 'nodule', 'what': 'a normal glandular lobule',
                'radius_mm': 3.0, 'surface_mm': [30.0, 1.0, 2.0], 'line_mm': [],
                'depth_mm': 5.0, 'bump_pct': bump, 'confounder': confounder,
                'marks': list(marks)}
    r = {'normal': [entry('nodule0', 25.4, True, [0]), entry('nodule1', 3.0, False)],
         'specificity': {'false_marks': 1, 'on_normal': 1, 'elsewhere': 0,
                         'normal_regions': 2, 'threshold_pct': 22.0}}
    conf, plain = normal_markers(r)
    assert (conf.status, conf.label) == ('confounder', 'nodule0: normal glandular lobule, '
                                                       '+25 %, false mark')
    assert (plain.status, plain.label) == ('normal', '')
    lines = normal_lines(r)
    assert lines[1] == ('stand out as much as a lesion (bump >= 22 %): nodule0 (a normal '
                        'glandular lobule, bump +25.4 %)')
    assert lines[2] == ('false mark 0 on nodule0: a normal glandular lobule, bump +25.4 %, '
                        'not a lesion')
