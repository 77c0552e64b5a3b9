"""objsearch.pipeline: derives the committed ``data/`` from public raw data.

Entry point ``build.build_data``. Modules: ``sources`` (reading raw files), ``frames`` (Unity <->
ROS REP-103), ``navgrid`` (viewpoint grid, door, starts), ``rooms``, ``room_objects``,
``alfred_poses`` and ``home`` (homes), ``vocabulary``, ``vg_prior``, ``scenario`` (paper Table I),
``schedule`` (paper Table II), ``provenance``, ``jsonio``, ``geometry``, ``sourceinfo``, ``errors``,
``findings`` (what a build refuses or reports) and ``accepted`` (the committed homes' findings).
"""
