"""Standby coordinators: which one is active, and when a standby takes over.

Every coordinator of a fleet runs the whole pipeline: it keeps copies of the robots'
maps, merges them and plans, from what the robots publish. Only the active one
publishes (assignments, merged map, anchors, its status) and answers map queries; a
standby stays silent and listens to the active's status and assignments.

- The active one's status carries ``leader`` = (its name, its term).
- A standby that has heard no active status for ``TAKEOVER_S`` (wall seconds), and
  sees no coordinator before it in order alive, becomes active with the highest term
  it heard plus one, and adopts the active's last assignments (nothing lost, nothing
  given twice; new target ids above every id it heard).
- Two actives (a partition healed): the one with the higher term wins, then the name
  first in order (``wins``); the other steps down to standby. Robots follow the same
  rule (``agents.robot``): they take assignments only from the leader they know.

    lead = Leadership("coordinator2", active=False)
    lead.heard_status(status, now)   # the active's: returns True if this one steps down
    lead.due(now, alive_names)       # True once this standby should take over
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

from protocols.messages import Assignment, CoordinatorStatus

log = logging.getLogger(__name__)

# no active coordinator heard this long (wall seconds): the liveliness lease (3 s) and a
# few cycles (statuses go out every cycle, 0.5-1 s), so a busy cycle is no takeover
TAKEOVER_S = 6.0


def wins(a: tuple[int, str], b: tuple[int, str]) -> bool:
    """Whether leader ``a`` = (term, name) prevails over ``b``: the higher term, then the
    name first in order."""
    return a[0] > b[0] or (a[0] == b[0] and a[1] < b[1])


@dataclass
class Leadership:
    name: str
    active: bool
    term: int = 0
    since: float = 0.0  # wall seconds (monotonic): started, or last heard an active
    leader: tuple[int, str] | None = None  # the active one heard last: (term, name)
    assignments: dict[str, Assignment] = field(default_factory=dict)  # the active's, heard
    max_target: int = -1  # the highest target id heard

    def heard_status(self, status: CoordinatorStatus, now: float) -> bool:
        """Another coordinator's status; True when this one, active, must step down."""
        if not status.leader or status.leader == self.name:
            return False
        other = (status.term, status.leader)
        self.since = now
        if self.leader is None or wins(other, self.leader) or other[1] == self.leader[1]:
            self.leader = other
        if self.active and wins(other, (self.term, self.name)):
            log.warning("%s: %s (term %d) is active: standing by", self.name, other[1], other[0])
            self.active = False
            return True
        return False

    def heard_assignment(self, robot: str, a: Assignment) -> None:
        if self.active:
            return
        self.assignments[robot] = a
        self.max_target = max(self.max_target, a.target)

    def due(self, now: float, alive: set[str]) -> bool:
        """A standby whose turn it is: no active status for ``TAKEOVER_S`` and no
        coordinator before it in order alive (``alive``: names, by liveliness)."""
        if self.active or now - self.since < TAKEOVER_S:
            return False
        return not any(n < self.name for n in alive if n != self.name)

    def take_over(self, now: float) -> None:
        self.term = (self.leader[0] if self.leader else self.term) + 1
        self.active, self.since = True, now
        log.warning(
            "%s: no active coordinator for %.0f s: taking over (term %d)",
            self.name,
            TAKEOVER_S,
            self.term,
        )


@dataclass
class Held:
    assignment: Assignment | None  # the new leader's last, held back while it was not


@dataclass
class Following:
    """A robot's side: the leader it takes assignments from (the one ``wins`` picks among
    the statuses it hears); another's assignments are held back, and the last one a
    coordinator sent is applied once it becomes the leader."""

    leader: tuple[int, str] | None = None
    held: dict[str, Assignment] = field(default_factory=dict)

    def admits(self, sender: str, a: Assignment) -> bool:
        if self.leader is None or sender == self.leader[1]:
            return True
        self.held[sender] = a
        return False

    def heard(self, status: CoordinatorStatus) -> Held | None:
        """A status; a ``Held`` when its sender is a new leader."""
        if not status.leader:
            return None
        other = (status.term, status.leader)
        if self.leader is not None and (other == self.leader or not wins(other, self.leader)):
            if other[1] == self.leader[1]:
                self.leader = other  # the same one, its term known better
            return None
        first = self.leader is None
        self.leader = other
        if not first:
            log.warning("following coordinator %s (term %d)", other[1], other[0])
        return None if first else Held(self.held.pop(other[1], None))
