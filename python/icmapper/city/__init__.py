"""City maps from many drives: every drive mapped (any method, learned or oracle detections), the
drive maps merged into one city map by the engine (``GlobalMap.merge_map``, a tree reduction), or
one map continued drive after drive; in-process or on Ray; evaluated across drives.

Modules: ``manifest`` (the city run folder's ``city.json``), ``drives`` (one drive -> its run
folder and its map), ``reduce`` (the tree of merges), ``ray_backend`` (drives as Ray tasks),
``run`` (build or extend a city run), ``evaluate`` (cross-drive ground truth and metrics),
``cli`` (``icmapper map --city``).
"""
