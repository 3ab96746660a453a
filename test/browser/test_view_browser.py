"""The view in a real browser (Debian's chromium, headless, software WebGL): what a person would
check on the debrief of a recorded session and on a live page fed by ROS topics.

Skipped, saying why, where chromium or viser is absent (.ci/run installs chromium)."""
import json
import re
import time

import numpy as np
import pytest

pytest.importorskip('viser', reason='the view extra (pip install .[view]) is not installed')

from haptic_anfis.view.browser import chromium, free_port, screenshot  # noqa: E402

from _view_bag import write_session_bag  # noqa: E402

pytestmark = pytest.mark.skipif(chromium() is None,
                                reason='chromium is not installed (apt-get install chromium)')

#: the scene's part of the 1280 x 800 window: left of the GUI panel, clear of the axes gizmo
SCENE = (slice(100, 700), slice(150, 900))   # rows, columns


def drawn(png) -> bool:
    """The scene arrived: the breast covers a fifth of the scene part of the window (a capture
    before the page received it is white there)."""
    px = pixels(png)
    return px['drawn'] > 0.2 * px['total']


def pixels(png):
    from PIL import Image
    a = np.asarray(Image.open(png).convert('RGB')).astype(int)[SCENE]
    r, g, b = a[..., 0], a[..., 1], a[..., 2]
    return {'drawn': int(((r < 235) | (g < 225) | (b < 225)).sum()),   # not the white page
            'red': int(((r > g + 60) & (r > b + 60)).sum()),          # deep coverage
            'yellow': int(((r > 200) & (g > 170) & (b < 150)).sum()),  # light coverage
            'green': int(((g > r + 40) & (g > b + 20)).sum()),         # a lesion found
            'blue': int(((b > r + 80) & (b > g + 50)).sum()),          # the probe
            'total': int(r.size)}


def test_debrief_page_shows_the_report_heat_map_and_lesions(tmp_path, capfd):
    from haptic_anfis.cli import main
    from haptic_anfis.view.build import open_bag_view
    bag = tmp_path / 'session'
    write_session_bag(bag)
    assert main(['exam', 'report', str(bag), '--json']) == 0
    want = json.loads(capfd.readouterr().out.strip().splitlines()[-1])
    app = open_bag_view(bag, port=free_port())
    try:
        px = pixels(screenshot(app.url, tmp_path / 'debrief.png', app=app, ready=drawn))
        assert px['drawn'] > 0.15 * px['total'], px   # the breast fills the middle of the view
        assert px['red'] > 2000 and px['yellow'] > 1000, px   # deep and light coverage painted
        assert px['green'] > 200, px   # the lesion found, revealed
        # the panel's numbers as the server holds them for every page: exam report --json's
        n = app.state()['numbers_text']
        for text in (f"score **{want['score']:.0f}**",
                     f"lumps found: **{want['hits']} of {want['hits'] + want['misses']}**",
                     f"false marks: **{want['false_marks']}**",
                     f"deep **{want['coverage_pct']['deep']:.0f} %**",
                     f"light **{want['coverage_pct']['light']:.0f} %**"):
            assert text in n, text
        app.scrub(0.0)   # the instructor drags the replay to the start; a page (re)connecting
        px0 = pixels(screenshot(app.url, tmp_path / 'start.png', app=app, ready=drawn))   # now gets that state
        assert px0['red'] < 0.05 * px['red'] and px0['drawn'] > 0.15 * px0['total'], px0
        assert px0['green'] > 200, px0   # the lesions stay revealed over the replay
    finally:
        app.close()


def test_live_page_from_ros_topics_draws_probe_and_dent_and_hides_lesions(tmp_path,
                                                                          monkeypatch):
    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    monkeypatch.setenv('ROS_DOMAIN_ID', '116')
    from haptic_anfis.nodes.web_view import web_view_in_thread
    with web_view_in_thread({'port': free_port()}, 'fake_loop') as (node, feeder):
        held_press(node, feeder, tmp_path)
        # bytes that are no contact message: counted and skipped, the page keeps drawing
        from sensor_msgs.msg import JointState

        from haptic_anfis import interfaces as ifc
        bad = feeder.create_publisher(JointState, ifc.TOPIC_CONTACT, 10)
        frames = node.app.stats.probe_updates
        end = time.monotonic() + 30.0
        while time.monotonic() < end and node.malformed == 0:
            bad.publish(b'\x00\x01\x00\x00\x01\x00')
            time.sleep(0.05)
        assert node.malformed > 0
        end = time.monotonic() + 10.0
        while time.monotonic() < end and node.app.stats.probe_updates <= frames + 3:
            time.sleep(0.05)
        assert node.app.stats.probe_updates > frames + 3


def held_press(node, feeder, tmp_path):
    """Publish a held press (pose, contact, force) at 100 Hz until the page draws it (at most
    60 s), then look at the page."""
    from geometry_msgs.msg import PoseStamped, WrenchStamped
    from sensor_msgs.msg import JointState

    from haptic_anfis import interfaces as ifc
    pubs = {t: feeder.create_publisher(m, t, 10) for t, m in (
        (ifc.TOPIC_POSE, PoseStamped), (ifc.TOPIC_CONTACT, JointState),
        (ifc.TOPIC_COMMAND, WrenchStamped))}
    y, z, depth = 0.02, 0.01, 0.006
    x = 0.045 * np.sqrt(1 - (y / 0.07) ** 2 - (z / 0.07) ** 2)

    def drawn_press() -> bool:
        st = node.app.stats
        return st.probe_position is not None and np.allclose(
            st.probe_position, (x - depth, y, z), atol=1e-9) and node.app.displacement is not None

    end = time.monotonic() + 60.0   # discovery and the first frames on a loaded machine
    while time.monotonic() < end and not drawn_press():   # a held press, 100 Hz
        p = PoseStamped()
        p.header.frame_id = 'tissue'
        p.pose.position.x, p.pose.position.y, p.pose.position.z = x - depth, y, z
        c = JointState(name=list(ifc.CONTACT_FIELDS))
        v = [0.0] * len(ifc.CONTACT_FIELDS)
        v[0:3], v[ifc.I_DEPTH], v[ifc.I_DX], v[ifc.I_IN_CONTACT] = [x, y, z], depth, -1.0, 1.0
        c.position = v
        w = WrenchStamped()
        w.wrench.force.x = 4.0
        for t, m in ((ifc.TOPIC_POSE, p), (ifc.TOPIC_CONTACT, c), (ifc.TOPIC_COMMAND, w)):
            pubs[t].publish(m)
        time.sleep(0.01)
    s = node.app.state()
    assert s['mode'] == 'live' and not s['lesions_visible']
    assert node.app.stats.probe_position is not None
    np.testing.assert_allclose(node.app.stats.probe_position, (x - depth, y, z), atol=1e-9)
    assert node.app.displacement is not None   # the dent is drawn
    px = pixels(screenshot(node.app.url, tmp_path / 'live.png', app=node.app, ready=drawn))
    assert px['drawn'] > 0.15 * px['total'], px
    assert px['blue'] > 300, px   # the probe
    assert px['green'] < 50, px   # no lesion marker
    s = node.app.state()   # the newest of each topic: the gauge
    assert 'pressure: **medium**' in s['gauge_text'] and 'force **4.0 N**' in s['gauge_text']
    # the force arrow is one scene node, moved frame after frame (not re-created)
    first = node.app.arrow
    time.sleep(0.3)   # ~9 frames of the same press
    assert node.app.arrow is first
    from haptic_anfis.view.app import FORCE_SCALE
    tip = np.array([x - depth, y, z])
    np.testing.assert_allclose(node.app.arrow.points[0],
                               [tip, tip + FORCE_SCALE * np.array([4.0, 0, 0])], atol=1e-6)


def test_live_page_shows_the_whole_region_what_is_left_to_palpate_the_cue_and_the_marks(
        tmp_path):
    """What a trainee must see while palpating, looked at in chromium: the region to examine
    outlined, both its side edges in view (the frontal camera), its not-yet-palpated skin in
    the neutral apart from the dimmed skin outside it, pressure painted up to the edge, the cue
    as a banner, a mark as soon as it is placed; and no machine health on the page."""
    from haptic_anfis.view.app import ViewApp, coverage_fractions
    from haptic_anfis.view.build import case_view
    cv = case_view(None)
    app = ViewApp(cv.vertices, cv.faces, cv.region_faces, cv.config.thresholds, port=free_port(),
                  deformation=cv.deformation)
    try:
        app.set_exam_running(True)
        g = cv.session.grid
        y = g.centroids[:, 1]
        lv = np.zeros(len(y), int)
        lv[(y < y.min() + 0.008) | (y > y.max() - 0.008)] = 3   # both side edges, deep
        app.set_coverage(lv, coverage_fractions(g, lv))
        centre = g.centroids[np.argmin(np.linalg.norm(g.centroids[:, 1:], axis=1))]
        n = centre / np.linalg.norm(centre)
        app.show_mark(centre + np.array([0.0, 0.0, 0.025]))
        d = cv.config.thresholds[-1] + 0.0005
        app.show_live(centre - d * n, (centre, -n, d), 3.0 * n, 12.0)
        px = looks(screenshot(app.url, tmp_path / 'live.png', app=app, ready=drawn))
        assert px['outline_left'] > 300 and px['outline_right'] > 300, px   # both edges in view
        # either side edge's deep paint in full view, as much of one as of the other (from the
        # side, as the camera was, the far edge showed a fifth of the near one's)
        assert min(px['red_left'], px['red_right']) > 1500, px
        assert min(px['red_left'], px['red_right']) > 0.6 * max(px['red_left'], px['red_right'])
        assert px['neutral'] > 20000, px   # the region's skin still to palpate
        assert px['outside'] > 10000, px   # the dimmed skin outside it
        assert px['mark'] > 30, px   # the mark, placed live
        s = app.state()
        assert s['cue'].startswith("that's right: deep") and 'font-size:1.5em' in s['banner']
        assert s['live_marks'] == 1
        app.show_live(centre - 0.003 * n, (centre, -n, 0.003), 1.0 * n, 13.0)
        time.sleep(1.1)   # held short of deep for longer than LIGHT_PRESS_S
        app.show_live(centre - 0.003 * n, (centre, -n, 0.003), 1.0 * n, 14.0)
        assert app.state()['cue'].startswith('press harder')
        assert not any('haptic loop' in str(v) for v in app.state().values())
        # the exam ends: the banner says so at once (grey), no "running" with a stopped clock
        app.show_over()
        from PIL import Image
        png = screenshot(app.url, tmp_path / 'over.png', app=app, ready=drawn)
        panel = np.asarray(Image.open(png).convert('RGB')).astype(int)[60:260, 940:1270]
        grey = (np.abs(panel - 153) <= 6).all(axis=2)   # OUTCOME['void'], the banner's
        assert grey.sum() > 3000, grey.sum()
        assert 'running' not in app.state()['status']
    finally:
        app.close()


def looks(png) -> dict:
    """Pixel counts of the live page's scene: the outline (dark neutral) and deep red left and
    right of the breast's middle, the not-palpated neutral, the dimmed outside skin, the marks'
    sky blue."""
    from PIL import Image
    a = np.asarray(Image.open(png).convert('RGB')).astype(int)[SCENE]
    r, g, b = a[..., 0], a[..., 1], a[..., 2]
    spread = np.max(a, axis=2) - np.min(a, axis=2)
    cols = np.arange(a.shape[1])[None, :].repeat(a.shape[0], axis=0)
    mid = int(np.median(cols[(r < 235) | (g < 225) | (b < 225)]))   # the breast's middle column
    outline = (spread < 14) & (r < 120)
    red = (r > g + 60) & (r > b + 60)
    return {'outline_left': int((outline & (cols < mid - 60)).sum()),
            'outline_right': int((outline & (cols > mid + 60)).sum()),
            'red_left': int((red & (cols < mid - 60)).sum()),
            'red_right': int((red & (cols > mid + 60)).sum()),
            'neutral': int(((spread < 14) & (r > 150) & (r < 250)).sum()),
            'outside': int(((r > g + 12) & (g > b) & (r < 200) & (r > 60)).sum()),
            'mark': int(((b > r + 80) & (g > r + 75) & (b > g + 20)).sum())}


def test_debrief_with_history_fits_a_1280_by_800_window(tmp_path):
    """The instructor's review of a recording with the trainee's history, in a 1280 x 800
    chromium: no table wider than the panel or running out of the window (the history was cut
    off on the right), the numbers rounded, the gauge (live only) gone."""
    from haptic_anfis.record.store import store_session
    from haptic_anfis.view.browser import Page, close_chromium, open_chromium
    from haptic_anfis.view.build import bag_debrief, open_bag_view
    bag, db = tmp_path / 'session', tmp_path / 'r.sqlite'
    write_session_bag(bag)
    rep = {k: v for k, v in bag_debrief(bag).report.items() if k != 'bag'}
    for k in range(7):
        store_session(db, 'ann', dict(rep, case='lib_m_dense_idc10_d10'), case_level=1,
                      bag=f'/bags/s{k}', started_utc='2026-12-01T10:00:00Z')
    app = open_bag_view(bag, None, free_port(), '127.0.0.1', None, 'ann', db)
    proc = open_chromium(app.url, (1280, 800))
    try:
        page = Page(proc, (1280, 800), 90.0)
        js = ('JSON.stringify(Array.from(document.querySelectorAll("table")).map(t => '
              '[t.getBoundingClientRect().right, t.scrollWidth, t.parentElement.clientWidth, '
              't.innerText]))')
        end, tables = time.monotonic() + 120.0, []
        while time.monotonic() < end and not tables:
            time.sleep(0.5)
            r = page.call('Runtime.evaluate', expression=js, returnByValue=True)
            tables = json.loads(r['result']['value'])
        assert tables, 'the history table never arrived'
        right, scroll, room, text = tables[0]
        assert '12-01' in text and 'retry' in text and 'lib_m_dense' not in text
        assert right <= 1280 and scroll <= room, tables[0]   # not cut off, no scrolling
        page.close()
    finally:
        close_chromium(proc)
        app.close()
    n = app.state()['numbers_text']
    assert 'duration **4 s**' in n and not re.search(r'\d\.\d\d', n), n   # rounded
    assert not app.g_bar.visible and not app.g_gauge.visible
