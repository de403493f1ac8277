"""Registration work done while a scan's views arrive (rangekit.registration.ahead.RegistrationAhead): the final
registration takes the levels, the first-round pairs, the joint refinement's overlaps and its first iteration's
correspondences, and gives the same poses, to the bit, as without them (issue 51: the joint refinement's first
iteration found ahead)."""

from __future__ import annotations

import numpy as np

from rangekit.app.process.register import turntable_registration
from rangekit.app.process.view_cache import cache_settings, table_transform, view_clouds
from rangekit.formats.sessions.session import Session
from rangekit.registration.ahead import RegistrationAhead
from rangekit.registration.multiview import register_views


def test_registration_ahead_gives_the_same_poses_and_its_first_joint_matches_are_taken(reference_session):
    session = Session.load(reference_session)
    rig = session.rig
    settings = cache_settings(session, "ray-ray", 0.002)
    clouds = [c for c, _ in view_clouds(session.done_views, session.pattern, rig, settings, session.capture.full_scale,
                                        table_transform(rig), 0.002, workers=1)]
    prior, options = turntable_registration(rig, session.done_views, clouds[0])
    assert options.voxel is not None and options.turntable
    ahead = RegistrationAhead(prior, options)
    for k, cloud in enumerate(clouds):   # as the views arrive
        ahead.add(k, cloud)
    with_ahead = register_views(clouds, init_T_world_view=prior, options=options, ahead=ahead)
    without = register_views(clouds, init_T_world_view=prior, options=options)
    assert np.array_equal(with_ahead.T_world_view, without.T_world_view)
    assert with_ahead.rmse == without.rmse
    assert ahead.taken["matches"] == len(ahead._matches) > 0    # every pair's both ways, from the first iteration
    assert ahead.taken["overlaps"] == len(ahead._joint)
