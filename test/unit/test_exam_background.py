"""A false mark on a normal nodule or a rib says which (exam specificity)."""
import numpy as np

from haptic_anfis.exam.findings import match
from haptic_anfis.exam.lesions import Lesion, subject_from_scene
from haptic_anfis.tissue.scene import SCENE_DIR, load_scene, surface_height

SCENE = SCENE_DIR / 'nod_s_fatty_two_ribs.yaml'


def _over(scene, y, z):
    return np.array([float(surface_height(np.array(y), np.array(z), scene.radii)), y, z])


def test_marks_on_a_nodule_a_rib_and_plain_fat_are_false_and_say_which():
    scene = load_scene(SCENE)
    bg = scene.background
    n = bg.nodules[3]
    # a (y, z) over a rib's line, clear of every nodule and the lesion
    rib = bg.ribs[0]
    ys = np.linspace(-0.03, 0.03, 61)
    y_rib = next(y for y in ys if bg.region_at(y, rib.z) == (rib.name, 'a rib'))
    # a point over none of them: far out on the diagonal between ribs
    plain = next((y, z) for y in ys for z in (-0.03, 0.0, 0.03)
                 if bg.region_at(y, z, 0.002) is None)
    t = scene.tumours[0]
    les = (Lesion(t.name, t.centre, t.radius),)
    lp = np.array([_over(scene, *t.centre[1:])])
    marks = np.array([_over(scene, n.centre[1], n.centre[2]), _over(scene, y_rib, rib.z),
                      _over(scene, *plain), lp[0]])
    fin = match(les, lp, marks, [None] * 4, 0.002, [True], bg)
    res = [m['result'] for m in fin['marks']]
    assert res == ['false', 'false', 'false', 'hit']
    assert fin['marks'][0]['reason'] == f'no lesion here: a normal glandular lobule ({n.name})'
    assert fin['marks'][1]['reason'] == f'no lesion here: a rib ({rib.name})'
    assert fin['marks'][2]['reason'] == 'no lesion within radius + margin'
    assert fin['false_marks'] == 3 and fin['false_marks_normal'] == 2
    # without the background (a smooth case) nothing changes
    plain_fin = match(les, lp, marks, [None] * 4, 0.002, [True])
    assert plain_fin['false_marks_normal'] == 0
    assert all(m['reason'] == 'no lesion within radius + margin'
               for m in plain_fin['marks'][:3])


def test_the_exam_subject_of_a_nodular_scene_carries_its_background():
    s = subject_from_scene(SCENE)
    assert s.background is not None and len(s.background.ribs) == 4
    assert subject_from_scene(SCENE_DIR / 'lib_s_fatty_two.yaml').background is None


def test_fat_lobules_in_a_dense_breast_are_named_as_such():
    bg = load_scene(SCENE_DIR / 'nod_s_dense_fib8_d10.yaml').background
    n = bg.nodules[0]
    assert bg.region_at(n.centre[1], n.centre[2]) == (n.name, 'a fat lobule')
