"""Seed-protocol cases at a chosen size, for the reconstruction benchmark (Table 1, Table 2, the
sensitivity and scaling sweeps).

``protocol_case("cabinet", 0)`` is the catalogue's ``protocol_cabinet_0`` unchanged; the size
options (views, frames, image size) and the repetition ``seed`` make variants of it without
touching the catalogue.  Repetition seed 0 keeps the catalogue's object seed (100 + instance);
seed s > 0 uses 100 + instance + 1000·s, which re-draws both the object's dimensions and the
sensor noise (one seed drives both in :class:`~kinemaforge_opt.synth.case.Case`).
"""

from __future__ import annotations

import dataclasses

from kinemaforge_opt.synth.case import Case

from .catalogue import get_case

SEED_STRIDE = 1000


def protocol_case(category: str, instance: int, seed: int = 0, views: int | None = None, frames: int | None = None,
                  width: int | None = None, height: int | None = None) -> Case:
    """The seed-protocol case ``protocol_<category>_<instance>`` with the given repetition seed
    and size (None keeps the catalogue's value).  The name records every change, e.g.
    ``protocol_cabinet_0@s1,v4,f12,160x120``."""
    base = get_case(f"protocol_{category}_{instance}")
    changes, tags = {}, []
    if seed:
        changes["seed"] = base.seed + SEED_STRIDE * seed
        tags.append(f"s{seed}")
    if views is not None and views != base.views:
        changes["views"] = views
        tags.append(f"v{views}")
    if frames is not None and frames != base.frames:
        changes["frames"] = frames
        tags.append(f"f{frames}")
    w, h = width or base.width, height or base.height
    if (w, h) != (base.width, base.height):
        changes["width"], changes["height"] = w, h
        tags.append(f"{w}x{h}")
    name = base.name + ("@" + ",".join(tags) if tags else "")
    return dataclasses.replace(base, name=name, **changes)
