"""Double-buffered ray casters, so that a rejected geometry proposal costs nothing.

This module imports only :mod:`albedo_model.render.raycast`.
"""

from __future__ import annotations

import numpy as np

from albedo_model.render.raycast import RayCaster

__all__ = ["SceneSlots"]


class SceneSlots:
    """Two ray casters over one topology, so that a rejected proposal costs nothing.

    ``current`` holds the accepted geometry. A geometry proposal writes its
    vertices into the spare caster (:meth:`propose`, an in-place refit) and casts
    with :attr:`candidate`; :meth:`accept` makes the spare current (a swap of two
    references), :meth:`reject` just forgets it, leaving ``current`` and its hits
    untouched. Proposals that do not move vertices (pose, camera, light, ...)
    use ``current`` directly (``candidate`` is ``current`` while nothing is
    pending). The spare is built on the first :meth:`propose`.

    Parameters
    ----------
    vertices : (n, 3) float array, model frame
    triangles : (m, 3) int array
    **caster_options
        Passed to :class:`RayCaster` (``threads``, ``robust``, ``update``).
    """

    def __init__(self, vertices: np.ndarray, triangles: np.ndarray, **caster_options):
        self._options = caster_options
        first = RayCaster(vertices, triangles, **caster_options)
        self._slots: list[RayCaster | None] = [first, None]
        self._pending = False

    @property
    def current(self) -> RayCaster:
        """Caster of the accepted geometry."""
        return self._slots[0]

    @property
    def candidate(self) -> RayCaster:
        """Caster of the proposed geometry, or ``current`` when nothing is pending."""
        return self._slots[1] if self._pending else self._slots[0]

    @property
    def pending(self) -> bool:
        """True while a proposed geometry awaits :meth:`accept` or :meth:`reject`."""
        return self._pending

    def propose(self, vertices: np.ndarray) -> RayCaster:
        """Load candidate vertices into the spare caster and return it."""
        spare = self._slots[1]
        if spare is None:
            spare = RayCaster(vertices, self._slots[0].triangles, **self._options)
            self._slots[1] = spare
        else:
            spare.update_vertices(vertices)
        self._pending = True
        return spare

    def accept(self) -> None:
        """Make the pending candidate current (no-op when nothing is pending)."""
        if self._pending:
            self._slots.reverse()
            self._pending = False

    def reject(self) -> None:
        """Drop the pending candidate; ``current`` is unchanged."""
        self._pending = False
