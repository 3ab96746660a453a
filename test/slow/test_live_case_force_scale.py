"""A case chosen live on the browser console of a running graph (the simulated Falcon's driver,
contact detector and force server, the web_view node on their context): the driver renders the
new case's force mapping from then on, and the page's gauge marks the clamp under it."""
from __future__ import annotations

import pytest

rclpy = pytest.importorskip('rclpy')
pytest.importorskip('viser')
from rclpy.parameter import Parameter  # noqa: E402

from haptic_anfis.cases.force_mapping import case_force_mapping, tissue_clamp  # noqa: E402
from haptic_anfis.cases.library import library  # noqa: E402
from haptic_anfis.device import native_tick as nt  # noqa: E402
from haptic_anfis.nodes.web_view import WebView  # noqa: E402
from haptic_anfis.session import SessionSpec, open_graph  # noqa: E402
from haptic_anfis.view.browser import free_port  # noqa: E402

FIRST, THEN = 'normal', 'lib_m_dense_idc20_d12'


def test_a_case_chosen_live_is_rendered_with_its_own_force_scale():
    spec = SessionSpec(nodes=('falcon_driver', 'contact_detector', 'force_server'), case=FIRST)
    views: list[WebView] = []

    def web_view(ctx):
        views.append(WebView(context=ctx, parameter_overrides=[
            Parameter('port', value=free_port()), Parameter('console_port', value=free_port()),
            Parameter('case', value=FIRST)]))
        return views[-1]

    g = open_graph(spec, extra=[web_view])
    try:
        page = views[0]
        assert g.wait_ready(300) is not None
        first = case_force_mapping(library().get(FIRST)).force_scale
        then = case_force_mapping(library().get(THEN)).force_scale
        assert g.driver.mapping.force_scale == pytest.approx(first) and then != pytest.approx(first)
        page.console.on_case(THEN)
        assert g.spin_for(120, until=lambda: page.choices.switch is None and page.page.name == THEN)
        assert 'falcon_driver' in page.console.last_message.split('switched: ')[1]
        for scale in (g.driver.mapping.force_scale, g.driver.input.mapping.force_scale,
                      g.driver.servo.cfg[nt.CFG.force_scale]):
            assert scale == pytest.approx(then)
        # the servo trace converts the ticks before the switch with the first scale
        assert [x for _, x in g.driver.loop.force_scales] == pytest.approx([first, then])
        assert page.app.max_force == pytest.approx(tissue_clamp(library().get(THEN)))
    finally:
        for v in views:
            v.close()
        g.shutdown()
