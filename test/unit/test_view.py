"""The browser view's room (haptic_anfis.view) without a browser: gauge, framing, debrief numbers
against ``exam report --json``, the server's state, and bad input named in one line."""
import json
import socket
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip('viser', reason='the view extra (pip install .[view]) is not installed')

from haptic_anfis.cli import main  # noqa: E402
from haptic_anfis.exam.config import ExamConfig  # noqa: E402
from haptic_anfis.view import frame_camera, gauge, lesion_status, probe_quaternion  # noqa: E402
from haptic_anfis.view.browser import free_port  # noqa: E402

from _view_bag import write_session_bag  # noqa: E402


@pytest.fixture(scope='module')
def bag(tmp_path_factory):
    p = tmp_path_factory.mktemp('view') / 'session'
    write_session_bag(p)
    return p


def last_json(out: str) -> dict:
    return json.loads(out.strip().splitlines()[-1])


def test_gauge_bands_follow_the_exam_levels_and_cue_light_and_overforce():
    th = ExamConfig().thresholds
    assert gauge(th[0] - 1e-4, 1.0, th, True).level == 'none'
    assert gauge(th[0], 1.0, th, True).level == 'light'
    assert gauge(th[1], 1.0, th, True).level == 'medium'
    assert gauge(th[2], 1.0, th, True).level == 'deep'
    assert gauge(th[2], 1.0, th, False).level == 'none'   # not in contact: no pressure
    assert gauge(th[1], 3.0, th, True, light_for=0.5).cue == ''
    assert 'press harder' in gauge(th[1], 3.0, th, True, light_for=1.5).cue
    good = gauge(th[2], 3.0, th, True, light_for=5.0)   # deep: said to be right
    assert good.cue.startswith("that's right: deep") and good.kind == 'good'
    assert gauge(th[1], 3.0, th, True, light_for=1.5).kind == 'fix'
    assert gauge(th[2], 3.0, th, False).cue == ''   # lifted: nothing to say
    assert "device's force" in gauge(th[2], 10.0, th, True, max_force=10.0).cue
    assert 0 <= gauge(0.1, 1.0, th, True).percent <= 100


def test_camera_frames_the_breast():
    rng = np.random.default_rng(0)
    v = rng.uniform((0, -0.07, -0.07), (0.045, 0.07, 0.07), (500, 3))
    f = frame_camera(v)
    d = np.subtract(f.look_at, f.position)
    dist = np.linalg.norm(d)
    assert 0.1 < dist < 1.0   # viser's default sits 5 m away
    rays = v - np.asarray(f.position)
    ang = np.arccos(rays @ d / np.linalg.norm(rays, axis=1) / dist)
    assert ang.max() < f.fov / 2   # every point inside the (vertical) field of view
    assert f.near < dist - 0.1 and f.far > dist + 0.1


@pytest.mark.parametrize('d', [(-1, 0, 0), (0, 1, 0), (0, 0, 1), (0, 0, -1), (-0.6, 0.3, 0.74)])
def test_probe_quaternion_stands_the_probe_out_of_the_tissue(d):
    w, x, y, z = probe_quaternion(d)
    q = np.array([x, y, z])
    # rotate +z by the quaternion
    v = np.array([0.0, 0.0, 1.0])
    r = v + 2 * w * np.cross(q, v) + 2 * np.cross(q, np.cross(q, v))
    np.testing.assert_allclose(r, -np.asarray(d) / np.linalg.norm(d), atol=1e-12)


def test_lesion_status():
    assert lesion_status({'found': True}) == 'hit'
    assert lesion_status({'found': False}) == 'missed'
    assert lesion_status({'found': False, 'palpable': False}) == 'below device'


def test_the_debrief_says_from_which_pressure_level_a_lesion_is_felt():
    from haptic_anfis.view.debrief import lesion_why
    assert lesion_why({'found': False, 'missed': 'never palpated deep', 'level': 'medium',
                       'level_depth_mm': 5.0}) == ('never palpated deep; palpable from medium '
                                                   'pressure (5 mm)')
    assert lesion_why({'found': True, 'level': 'light', 'level_depth_mm': 2.0}) == (
        'found; palpable from light pressure (2 mm)')
    assert lesion_why({'found': False, 'palpable': False,
                       'missed': 'below what this device renders', 'reason': 'at most +4.1 %'}
                      ) == 'below what this device renders; at most +4.1 %'


def test_debrief_equals_exam_report_and_replays_in_time(bag, capfd):
    from haptic_anfis.view.build import bag_debrief
    assert main(['exam', 'report', str(bag), '--json']) == 0
    want = last_json(capfd.readouterr().out)
    d = bag_debrief(bag)
    n = d.numbers()
    assert n['hits'] == want['hits'] and n['misses'] == want['misses']
    assert n['false_marks'] == want['false_marks'] and n['score'] == want['score']
    assert n['coverage_deep_pct'] == want['coverage_pct']['deep']
    assert [(le.name, le.status) for le in d.lesions] == [
        (e['name'], 'hit' if e['found'] else 'missed') for e in want['lesions']]
    end = d.session.grid.level_per_face()
    early = d.face_levels(0.25 * d.duration)
    assert (early <= end).all() and early.sum() < end.sum()   # coverage grows over the replay
    assert len(d.marks(0.0)) == 0 and len(d.marks()) == want['samples']['marks']
    assert len(d.path(0.1 * d.duration)) < len(d.path())


def test_page_state_is_the_report_and_lesions_are_revealed(bag):
    from haptic_anfis.view.build import open_bag_view
    app = open_bag_view(bag, port=free_port())
    try:
        s = app.state()
        assert s['mode'] == 'debrief' and s['lesions_visible']
        n = s['numbers']
        assert f"score **{n['score']:.0f}**" in s['numbers_text']
        assert f"lumps found: **{n['hits']} of {n['hits'] + n['misses']}**" in s['numbers_text']
        assert 'replay' not in s['gauge_text'] and not app.g_bar.visible   # live only
        assert not app.g_gauge.visible and 'lump missed' in app.g_legend.content
        app.scrub(0.0)   # the start of the replay: nothing covered yet
        assert 'light 0.0 %' in app.state()['coverage_text']
    finally:
        app.close()


def test_live_page_hides_lesions_and_draws_the_dent():
    from haptic_anfis.view.app import ViewApp
    from haptic_anfis.view.build import case_view
    cv = case_view(None)
    app = ViewApp(cv.vertices, cv.faces, cv.region_faces, cv.config.thresholds,
                  port=free_port(), deformation=cv.deformation)
    try:
        app.set_exam_running(True, blind=True)
        y, z = 0.01, 0.0
        x = 0.045 * np.sqrt(1 - (y / 0.07) ** 2)
        frames = app.stats.skin_frames
        app.show_live(np.array([x - 0.006, y, z]),
                      (np.array([x, y, z]), np.array([-1.0, 0, 0]), 0.006), np.array([3.0, 0, 0]),
                      12.0)
        s = app.state()
        assert not s['lesions_visible'] and 'blind' in s['status']
        assert 'medium' in s['gauge_text'] and s['skin_frames'] == frames + 1
        assert np.abs(app.displacement).max() == pytest.approx(0.006)   # the probe's depth
        app.show_live(np.array([x + 0.01, y, z]), None, None, 13.0)   # lifted: dent gone
        assert app.displacement is None
        # the exam ends: said at once, and a late live frame does not bring "running" back
        app.show_over()
        s = app.state()
        assert s['mode'] == 'over' and 'exam over — debrief loading' in s['status']
        assert s['cue'] == 'exam over — debrief loading' and 'running' not in s['status']
        assert not app.probe.visible
        app.show_live(np.array([x - 0.006, y, z]),
                      (np.array([x, y, z]), np.array([-1.0, 0, 0]), 0.009), None, 14.0)
        assert app.state()['cue'] == 'exam over — debrief loading'
        assert app.g_clock.content == 'exam over'
        app.set_exam_running(True)   # the next exam: live again, no banner left over
        assert app.state()['mode'] == 'live' and app.state()['banner'] == ''
    finally:
        app.close()


def test_bad_input_is_one_line_naming_it(tmp_path, bag, capfd):
    assert main(['view', str(tmp_path / 'nope'), '--port', str(free_port())]) == 1
    err = capfd.readouterr().err
    assert 'nope' in err and len(err.strip().splitlines()) == 1
    bad = tmp_path / 'corrupt'
    bad.mkdir()
    (bad / 'metadata.yaml').write_text('rosbag2_bagfile_information: [not: a bag')
    assert main(['view', str(bad), '--port', str(free_port())]) == 1
    err = capfd.readouterr().err
    assert 'corrupt' in err and len(err.strip().splitlines()) == 1
    nocontact = tmp_path / 'nocontact'
    write_session_bag(nocontact, with_contact=False)
    assert main(['view', str(nocontact), '--port', str(free_port())]) == 1
    err = capfd.readouterr().err
    assert '/contact' in err and 'nothing to show' in err and len(err.strip().splitlines()) == 1
    assert main(['view', str(bag), '--case', 'no_such_case', '--port', str(free_port())]) == 1
    err = capfd.readouterr().err
    assert 'no_such_case' in err and len(err.strip().splitlines()) == 1
    with socket.socket() as s:
        s.bind(('127.0.0.1', 0))
        s.listen()
        port = s.getsockname()[1]
        assert main(['view', str(bag), '--port', str(port)]) == 1
        err = capfd.readouterr().err
        assert f'--port {port}' in err and 'in use' in err and len(err.strip().splitlines()) == 1


def test_debrief_lists_the_trainees_sessions_from_the_record(tmp_path, bag):
    from haptic_anfis.exam.from_bag import session_from_bag
    from haptic_anfis.record import store_session
    from haptic_anfis.view.build import open_bag_view
    db = tmp_path / 'record.sqlite'
    report, _ = session_from_bag(bag)
    for k in range(2):   # two recordings (one bag counts once)
        store_session(db, 't01', report, source='bag', bag=f'{bag}-{k}')
    app = open_bag_view(bag, port=free_port(), trainee='t01', db=db)
    try:
        table = app.g_history_md.content
        assert app.g_history.visible and '**t01**: 2 sessions' in table
        rows = [r for r in table.splitlines() if r.startswith('| ') and r[2].isdigit()]
        assert len(rows) == 2 and f"| {report['verdict']} |" in rows[-1]
    finally:
        app.close()
    app = open_bag_view(bag, port=free_port(), trainee='nobody', db=db)   # said, not raised
    try:
        assert app.g_history_md.content.startswith('trainee record: ')
        from haptic_anfis.view.escape import md
        assert md(str(db)) in app.g_history_md.content   # escaped, as every text shown
    finally:
        app.close()


def test_a_hung_chromium_is_killed_and_another_capture_tried(tmp_path, monkeypatch):
    """screenshot(): a chromium that stops answering (seen in CI) counts as one try, not as the
    test's or the shots' failure; all tries hung or never ready: one line saying so."""
    from haptic_anfis.view import browser
    calls = []

    def fake(url, out, size, timeout, settle, app, ready, before):
        calls.append(timeout)
        if len(calls) == 1:
            raise TimeoutError('chromium did not answer Page.captureScreenshot in 90 s')
        out.write_bytes(b'png')
        return True
    monkeypatch.setattr(browser, '_capture_when_ready', fake)
    assert browser.screenshot('http://x/', tmp_path / 'a.png').read_bytes() == b'png'
    assert len(calls) == 2

    def hang(*a):
        raise TimeoutError('chromium opened no DevTools port in 90 s')
    monkeypatch.setattr(browser, '_capture_when_ready', hang)
    with pytest.raises(RuntimeError, match='in 2 chromiums of 90 s .2 of them hung'):
        browser.screenshot('http://x/', tmp_path / 'b.png', tries=2, timeout=90)
    monkeypatch.setattr(browser, '_capture_when_ready', lambda *a: False)
    with pytest.raises(RuntimeError, match='did not connect, or was not ready, in 3 .*0 of'):
        browser.screenshot('http://x/', tmp_path / 'c.png', tries=3, timeout=90)


def test_skin_paint_sets_the_region_apart_and_maps_pressure_continuously():
    from haptic_anfis.palette import LEVEL, NOT_PRESSED, rgb255
    from haptic_anfis.view.scene import OUTSIDE_RGB, SkinPaint, pressure_rgb, region_outline
    # two triangles sharing an edge, the first is the region; a third vertex-disjoint outside
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [5, 5, 0], [6, 5, 0], [5, 6, 0]],
                 float) * 0.01
    f = np.array([[0, 1, 2], [1, 3, 2], [4, 5, 6]])
    th = (0.002, 0.005, 0.008)
    p = SkinPaint(v, f, np.array([0, 1]), th)
    c = p.colours(p.vertex_levels(np.array([0, 3])))
    assert tuple(c[0, :3]) == rgb255(NOT_PRESSED)   # in the region, not palpated: the neutral
    assert tuple(c[3, :3]) == rgb255(LEVEL['deep'])  # a corner only of the deep face
    assert tuple(c[4, :3]) == OUTSIDE_RGB and tuple(c[6, :3]) == OUTSIDE_RGB
    assert c[4, :3].sum() < c[0, :3].sum()   # outside is dimmer than what is left to palpate
    # the border: the four outer edges of the two region triangles, not the shared one
    assert sorted(map(tuple, region_outline(f, np.array([0, 1])))) == [(0, 1), (0, 2), (1, 3),
                                                                      (2, 3)]
    # continuous: the level colours at the thresholds, between them in between, deep beyond
    r = pressure_rgb(np.array([0.0, 0.002, 0.0035, 0.005, 0.008, 0.02]), th)
    np.testing.assert_allclose(r[[0, 1, 3, 4]], [rgb255(NOT_PRESSED), rgb255(LEVEL['light']),
                                                 rgb255(LEVEL['medium']), rgb255(LEVEL['deep'])])
    np.testing.assert_allclose(r[2], 0.5 * (r[1] + r[3]))
    np.testing.assert_allclose(r[5], r[4])
    # a dent paints the pressed vertex in the continuous colour of its displacement
    u = np.zeros_like(v)
    u[0] = (0.0, 0.0, -0.005)
    assert tuple(p.colours(None, u)[0, :3]) == rgb255(LEVEL['medium'])


def test_gauge_html_ticks_each_band_and_the_banner_says_the_cue():
    from haptic_anfis.palette import OUTCOME
    from haptic_anfis.view.legend import banner_html, gauge_html, legend_html
    th = ExamConfig().thresholds
    h = gauge_html(th, None)
    for k, t in zip(('light', 'medium', 'deep'), th):   # a tick at each threshold, labelled
        assert f'left:{100 * t / (1.5 * th[-1]):.1f}%' in h and f'{k} {t * 1e3:.0f}' in h
    assert 'background:#000;' not in h   # no marker off the skin
    assert 'left:50.0%;top:-4px' in gauge_html(th, 0.75 * th[-1])   # the marker at the depth
    good = gauge(th[2], 3.0, th, True)
    assert OUTCOME['pass'] in banner_html(good.cue, good.kind) and "that's right" in \
        banner_html(good.cue, good.kind)
    assert OUTCOME['retry'] in banner_html('press harder', 'fix')
    assert banner_html('', '') == ''
    assert all(w in legend_html() for w in ('not yet palpated', 'deep', 'outside the region',
                                            'your marks'))


def test_debrief_numbers_are_rounded_as_a_person_reads_them():
    from haptic_anfis.view.panel import duration_text, history_markdown, numbers_markdown
    assert duration_text(183.719) == '3 min 4 s' and duration_text(42.4) == '42 s'
    assert duration_text(3725) == '1 h 2 min'
    n = {'score': 41.04, 'verdict': 'retry', 'hits': 0, 'misses': 1, 'false_marks': 2,
         'coverage_light_pct': 62.01, 'coverage_medium_pct': 61.5, 'coverage_deep_pct': 40.49,
         'pattern': 'vertical_strip', 'duration_s': 183.719,
         'time_at_level_s': {'light': 8.413, 'deep': 16.065}, 'area_time_s': None,
         'force_palpating_n': 0.292, 'force_searching_n': 9.232,
         'palpating_vs_searching_pct': -96.8}
    t = numbers_markdown(n)
    assert 'score **41**' in t and 'lumps found: **0 of 1**' in t and 'false marks: **2**' in t
    assert 'deep **40 %**' in t and 'duration **3 min 4 s**' in t and 'vertical strip' in t
    assert 'light 8 s · deep 16 s' in t and '0.3 / 9.2 N (-97 %)' in t
    assert '183.7' not in t and '62.01' not in t
    rows = [{'session': k, 'started_utc': '2026-12-01T10:00:00Z', 'case_level': 1,
             'coverage_pct': {'deep': 70.2}, 'hits': 1, 'misses': 0, 'false_marks': 0,
             'score': 88.4, 'verdict': 'pass', 'case': 'lib_m_dense_idc10_d10'} for k in range(12)]
    h = history_markdown('ann', rows)
    assert h.count('\n| ') == 1 + 5 and '| 11 | 12-01 | 1 | 70 % | 1/1 | 0 | 88 | pass |' in h
    assert 'lib_m_dense' not in h   # no case name: narrow, and no blind case named


def test_a_revealed_lesion_says_how_much_it_stood_out_and_its_difficulty():
    """From the case's FE grading: the contrast at deep pressure (8 mm) and the difficulty,
    carried by the exam's lesion entries into the debrief's words."""
    from haptic_anfis.cases import library
    from haptic_anfis.exam.lesions import subject_from_scene
    from haptic_anfis.view.debrief import lesion_why
    case = library().get('lib_l_dense_three')
    grade = {g['lesion']: g for g in case.grading()['lesions']}['idc1']
    want = next(r['contrast_pct'] for r in grade['contrasts'] if abs(r['depth_m'] - 0.008) < 1e-9)
    les = {le.name: le for le in subject_from_scene(case.scene_path).lesions}['idc1']
    assert les.contrast_pct == pytest.approx(want) and les.contrast_depth == pytest.approx(0.008)
    assert les.difficulty == grade['difficulty']
    why = lesion_why({'found': False, 'missed': 'never palpated deep', 'level': les.level,
                      'level_depth_mm': les.level_depth * 1e3, 'contrast_pct': les.contrast_pct,
                      'contrast_depth_mm': 8.0, 'difficulty': les.difficulty})
    assert why.endswith(f'stood out {want:.0f} % at deep pressure; difficulty '
                        f"{grade['difficulty']} of 5"), why


def test_feel_it_again_presses_the_lesion_at_each_band_then_beside_it(bag, tmp_path):
    import yaml

    from haptic_anfis.device.palpation import PalpationScript, dome_height
    from haptic_anfis.view.build import bag_debrief
    from haptic_anfis.view.feel_again import OVERSHOOT
    d = bag_debrief(bag)
    cmds = d.feel_again(tmp_path)
    les = d.report['lesions'][0]
    cmd = cmds[les['name']]
    assert cmd.startswith('haptic-anfis sim --case default --view --duration 120 --params-file ')
    params = yaml.safe_load(open(cmd.split('--params-file ')[1]))
    script = PalpationScript.from_yaml(params['falcon_driver']['ros__parameters'][
        'palpation_script'])
    y, z = les['surface_mm'][1] * 1e-3, les['surface_mm'][2] * 1e-3
    t = np.linspace(0.0, script.duration, 4000)
    held = np.array([script.target(x) for x in t if script.is_pressing(x)])
    over = np.hypot(held[:, 1] - y, held[:, 2] - z) < 1e-6
    assert over.any() and (~over).any()   # over the lesion, and beside it
    depth = dome_height(y, z, (0.045, 0.07, 0.07)) - held[over, 0]
    th = d.session.config.thresholds
    assert depth.max() == pytest.approx(OVERSHOOT * th[-1], abs=1e-4)   # the deep band's press
    assert np.hypot(held[~over, 1] - y, held[~over, 2] - z).min() > les['radius_mm'] * 1e-3
    # a blind exam's debrief names no case, so it has no such step
    d.report['case'] = 'blind case'
    assert d.feel_again(tmp_path) == {}


def test_the_debrief_shows_the_normal_background_beside_the_lesions():
    """A nodular case with ribs: after the exam its lobules and ribs are drawn on the page with
    a legend, the panel says the background and the false mark on a rib."""
    from haptic_anfis.view.app import ViewApp
    from haptic_anfis.view.build import case_view
    from haptic_anfis.view.debrief import Debrief
    cv = case_view('nod_s_fatty_two_ribs', dent=False)   # its skin: the scene's breast
    s = cv.session
    from haptic_anfis.exam.normal import skin_point
    bg, margin = s.subject.background, cv.config.hit_margin
    ribs = {e['name']: e for e in s.report()['normal'] if e['kind'] == 'rib' and e['line_mm']}
    lesions = [(*les.centre[1:], les.radius) for les in s.subject.lesions]
    name, y = next((b.name, y) for b in bg.ribs if b.name in ribs   # on the rib, off the lobules
                   for y in np.arange(-0.03, 0.03, 0.001)           # and the lesions
                   if bg.region_at(y, b.z, margin) == (b.name, 'a rib')
                   and all(np.hypot(y - c[0], b.z - c[1]) > c[2] + margin + 0.002
                           for c in lesions))
    rib = ribs[name]
    s.add_mark(1.0, skin_point(s.surface.detector, y, next(b.z for b in bg.ribs
                                                            if b.name == name)))
    r = s.report()
    assert r['false_marks'] == 1 and r['false_marks_normal'] == 1
    app = ViewApp(cv.vertices, cv.faces, cv.region_faces, cv.config.thresholds,
                  port=free_port())
    try:
        app.show_debrief(Debrief(r, s))
        st = app.state()
        drawn = {name for name, _, _ in st['normal']}
        assert drawn == {e['name'] for e in r['normal']
                         if e['kind'] == 'nodule' or e['line_mm']}
        assert (rib['name'], 'normal', f"{rib['name']}: rib, false mark") in st['normal']
        assert 'normal lobule / rib (no lump)' in app.g_legend.content
        assert '(1 on normal tissue)' in st['numbers_text']
        assert f"false mark 0 on {rib['name']}: a rib, not a lesion" in app.g_lesions.content
        assert 'normal background:' in app.g_lesions.content
        app.set_exam_running(True)   # the next exam: the background hidden again
        assert app.state()['normal'] == [] and 'normal lobule' not in app.g_legend.content
    finally:
        app.close()
