"""meshcat scenes of articulated models (the only package that imports meshcat).

    Scene().add_point_clouds(...), .add_model(model, group, q), .animate(model, motions), .save(path),
    .serve()                                 the same scene on a live meshcat server
    build_view(model, ...) -> Scene          the scene `kinemaforge view` writes
    decode_static_html(html) -> list[dict]   the meshcat commands inside a saved scene
"""

from .scene import Scene, decode_static_html, link_poses
from .view import build_view

__all__ = ["Scene", "build_view", "decode_static_html", "link_poses"]
