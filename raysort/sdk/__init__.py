"""raysort's plugin SDK: everything a plugin author needs, and nothing else.

A sorter, traversal, shader or generator, built in or from another package,
imports from here (and, in Cython, cimports the C layouts of
``raysort/_types.pxd`` and the traversal driver of ``raysort/sdk/driver.pxd``,
built against :func:`get_include`)::

    from raysort.sdk import Sorter, fixed_packets, integer

* **base classes** of the four plugin kinds, and the containers they read and
  write (:class:`RayBatch`, :class:`Packets`, :class:`Hits`, :class:`Paths`,
  :class:`Bounce`, :class:`ShadowRays`, :class:`Counters`), and
  :class:`LibraryTraversal`, the base of a traversal answered by an outside ray
  tracer (subclasses give its scene and query; see raysort-embree);
* **packet helpers** (:func:`fixed_packets`; :func:`plain_packets`, whether a
  kernel that checks large-packet boundaries itself may take them as they are;
  :func:`identity_order`, the order
  of a sorter that keeps the rays' order, which the contract check knows without
  reading it), the row indices of ray batches
  and gathered packets (:class:`RayRow`, :class:`PacketRow`; prefer the named
  views such as ``packets.t``) and layout limits (:data:`MAX_PACKET`), all
  derived from ``raysort/include/raysort/types.h``;
* **parameter validators** (:func:`integer`, :func:`number`, :func:`boolean`,
  :func:`choice`, :func:`vector3`), which raise :class:`ConfigError` naming the parameter;
* **contract checks** (:func:`check_sort`, :func:`check_hits` with
  :func:`before_traversal`, :func:`check_counters`, :func:`check_generated`,
  :func:`check_bounce`, and :func:`check_packets` for large-packet
  boundaries), the same ones the pipeline runs on every plugin from outside
  raysort, for a plugin's own tests.
"""
from raysort.contract import (before_traversal, check_bounce, check_counters, check_generated,
                              check_hits, check_packets, check_sort)
from raysort.errors import ConfigError, PluginContractError
from raysort.orders import identity_order
from raysort.params import boolean, choice, integer, number, vector3
from raysort.paths import Bounce, Paths, ShadowRays
from raysort.plugin import Generator, Shader, Sorter, Traversal
from raysort.rays import MAX_PACKET, Hits, PacketRow, Packets, RayBatch, RayRow
from raysort.sdk.library import LibraryTraversal
from raysort.sdk.packets import fixed_packets, plain_packets
from raysort.stats import Counters


def get_include():
    """Directory to add to ``include_dirs`` to build a Cython plugin against raysort."""
    import raysort

    return raysort.get_include()


__all__ = [
    "Generator", "Sorter", "Traversal", "Shader", "LibraryTraversal",
    "RayBatch", "Packets", "Hits", "Paths", "Bounce", "ShadowRays", "Counters",
    "MAX_PACKET", "RayRow", "PacketRow", "fixed_packets", "plain_packets", "identity_order",
    "integer", "number", "boolean", "choice", "vector3",
    "check_sort", "check_hits", "before_traversal", "check_counters", "check_generated",
    "check_bounce", "check_packets", "ConfigError", "PluginContractError", "get_include",
]
