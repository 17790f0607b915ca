"""Registry of mesh builders: name -> (parameter dataclass, build function)."""

from __future__ import annotations

from geometry.specimens import BarParameters, DiscParameters, RingParameters, build_bar, build_disc, build_ring
from geometry.stator import StatorParameters, ThinRingParameters, build_stator, build_thin_ring
from geometry.transducer import TransducerParameters, build_transducer

BUILDERS = {
    "bar": (BarParameters, build_bar),
    "disc": (DiscParameters, build_disc),
    "ring": (RingParameters, build_ring),
    "transducer": (TransducerParameters, build_transducer),
    "stator": (StatorParameters, build_stator),
    "thin_ring": (ThinRingParameters, build_thin_ring),
}
