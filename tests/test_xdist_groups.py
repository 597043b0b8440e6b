"""`make test` runs on both cores with ``--dist loadgroup``: the tests of one ``xdist_group``
(the study's shared run, ArduSub's SITL) must stay on one worker, so a module fixture is built
once and two SITLs never compete. pytest-xdist marks a grouped test by suffixing its node id
with ``@group``; from pytest 9.2 that suffix no longer takes (pytest-dev/pytest-xdist#1386)
and the groups are silently split, which this test catches."""

import pytest

pytestmark = pytest.mark.xdist_group("grouping-check")


def test_a_grouped_test_carries_its_group_under_loadgroup(request):
    if not getattr(request.config.option, "loadgroup", False):
        pytest.skip("not run by pytest-xdist with --dist loadgroup (make test does)")
    assert request.node.nodeid.endswith("@grouping-check"), (
        f"{request.node.nodeid}: pytest-xdist's loadgroup did not group this test; "
        "this pytest splits the xdist groups (see pyproject.toml's test extra)"
    )
