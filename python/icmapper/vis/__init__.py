"""Seeing the map being built (issue 17): pictures, videos and an offline HTML viewer of runs.

One concept per module:

- ``replay``   a run folder paired with its source: per-frame predictions, camera images and
               ground truth recomputed from the source spec, and the global map so far;
- ``overlay``  map instances projected into camera images through the frame's camera geometry;
- ``frame``    the per-frame picture (cameras with overlays, BEV panel, global-map overview);
- ``video``    a drive's frames as an MP4 (imageio-ffmpeg) or, without an encoder, a GIF;
- ``viewer``   one self-contained HTML file (data and code inline) to scrub through a run;
- ``cli``      ``icmapper vis`` and ``icmapper view``.

Progress reporting lives in ``icmapper.progress`` (used by every long loop of the package).
Nothing here changes a run: these modules only read run folders and sources.
"""
