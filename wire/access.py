"""Who may do what through a cell's router: Zenoh's access control, by role.

A deployed router (``deploy/``) knows every session's user from Zenoh's
user/password authentication. :func:`access_control` turns users by role into
the router's ``access_control`` block. Every key in it comes from
:mod:`wire.keys`, so the rules name the keys the parts really use.

Roles (all but ``reconstruct`` act in one cell; ``reconstruct`` serves the pool
that every cell shares):

=============  =====================================================================
client         submit, list, status, result and cancel a cell's jobs; hear their events;
               read the cell's status, the robot's state and which parts are alive
observer       what a client reads, nothing more: no submit, no cancel
daemon         the cell daemon: serve the job keys, publish events, ask the robot (move
               and gripper) and the camera, send reconstructions to the pool and follow
               its workers
robot          the robot worker: serve move, gripper and state, publish the state
camera         the camera worker: serve capture, read the robot's state (the simulated
               camera renders from it) and hear the jobs' events (the simulated camera
               empties its workspace while a job takes backgrounds)
reconstruct    a reconstruction worker: serve the pool's keys, announce itself and beat,
               each only under its own worker id, which is its Zenoh user name
=============  =====================================================================

A reconstruction worker is trusted with no cell's robot, but a worker id stands for a
track record in the daemon's pool (``cell/pool.py``): so each ``reconstruct`` user is a
subject of its own, ``reconstruct:<user>``, whose rules name ``<user>`` as the worker id in
every pool key. No reconstruct user can then serve, announce or beat under another's id.

The router denies everything else: a query no rule allows is dropped, and so is
a queryable, a subscriber, a publication, a liveliness token or a reply. A user
in no role can do nothing at all; a user in several roles may do what each allows.

How Zenoh 1.10 decides (``zenoh/src/net/routing/interceptor/access_control.rs``
and ``authorization.rs``): the router checks each message a session sends it
(ingress) and each it sends a session (egress), against the rules of the
subjects the session's user matches. A rule applies when one of its key
expressions *includes* the message's key (``robocell/c/jobs/*`` includes
``robocell/c/jobs/42``, not ``robocell/c/**``), so a wildcard declaration or
query is refused unless a rule includes the whole wildcard. Replies are checked
on their own key, which robocell's queryables set to the query's key.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping

from . import keys

__all__ = ["ROLES", "POOL_ROLES", "USER_NAME", "PARTS", "permissions", "access_control", "pool_subject",
           "roles_that_may", "what_a_query_asks", "part_refusal"]

#: What a user name must match: the router's dictionary holds ``user:password`` lines.
USER_NAME = re.compile(r"[^:\s](?:[^:]*[^:\s])?")
#: Every role, in the order the documentation lists them.
ROLES = ("client", "observer", "daemon", "robot", "camera", "reconstruct")
#: Roles that act on the reconstruction pool, shared by every cell, rather than in one cell.
POOL_ROLES = frozenset({"reconstruct"})

# What a verb of :func:`permissions` lets a session do, as (flow, Zenoh message) pairs: ingress
# messages are those the session sends the router, egress those the router sends it. A querier
# must receive replies, a queryable receive queries and send replies, a subscriber receive
# publications, a liveliness watcher receive tokens; a publisher needs no egress at all.
_MESSAGES: dict[str, tuple[tuple[str, str], ...]] = {
    "query": (("ingress", "query"), ("egress", "reply")),
    "serve": (("ingress", "declare_queryable"), ("ingress", "reply"), ("egress", "query")),
    "publish": (("ingress", "put"),),
    "subscribe": (("ingress", "declare_subscriber"), ("egress", "put")),
    "announce": (("ingress", "liveliness_token"),),
    "watch": (("ingress", "declare_liveliness_subscriber"), ("ingress", "liveliness_query"),
              ("egress", "liveliness_token")),
}


def _reads(cell: str) -> list[tuple[str, str]]:
    """What every user of a cell may read: the ground clients and observers share."""
    return [
        ("query", keys.jobs(cell)), ("query", keys.status(cell)), ("query", keys.job(cell, "*")),
        ("query", keys.result(cell, "*")), ("query", keys.robot_state(cell)),
        ("subscribe", keys.events(cell, "*")), ("subscribe", keys.robot_state(cell)),
        ("watch", keys.alive(cell)),
    ]


def permissions(role: str, cell: str, worker: str = "*") -> list[tuple[str, str]]:
    """What ``role`` may do in ``cell``, as (verb, key expression) pairs.

    The verbs: ``query`` (ask, and hear the answer), ``serve`` (answer queries),
    ``publish``, ``subscribe``, ``announce`` (declare a liveliness token) and ``watch``
    (follow liveliness tokens). A ``reconstruct`` worker's keys do not depend on ``cell``;
    they are those of worker id ``worker`` (the router gives each its own).

    Raises
    ------
    ValueError
        If ``role`` is not one of :data:`ROLES`, or ``worker`` is neither a worker id nor "*".

    >>> ("query", "robocell/cell1/jobs/*/cancel") in permissions("client", "cell1")
    True
    >>> [key for verb, key in permissions("observer", "cell1") if key.endswith("cancel")]
    []
    >>> ("publish", "robocell/_pool/heartbeat/recon1") in permissions("reconstruct", "cell1", "recon1")
    True
    """
    if role == "client":
        return [("query", keys.submit(cell)), ("query", keys.cancel(cell, "*")), *_reads(cell)]
    if role == "observer":
        return _reads(cell)
    if role == "daemon":
        return [
            ("serve", keys.submit(cell)), ("serve", keys.jobs(cell)), ("serve", keys.status(cell)),
            ("serve", keys.job(cell, "**")),   # a job's status, result and cancel
            ("publish", keys.events(cell, "*")),
            ("announce", keys.alive(cell, "daemon")), ("watch", keys.alive(cell)),
            ("query", keys.robot_move(cell)), ("query", keys.robot_grip(cell)), ("query", keys.camera_capture(cell)),
            ("query", keys.reconstructor("*")), ("query", keys.reconstructor_info("*")),
            ("watch", keys.RECONSTRUCTORS_ALIVE), ("subscribe", keys.RECONSTRUCTORS_HEARTBEAT),
        ]
    if role == "robot":
        return [("serve", keys.robot_move(cell)), ("serve", keys.robot_grip(cell)), ("serve", keys.robot_state(cell)),
                ("publish", keys.robot_state(cell)), ("announce", keys.alive(cell, "robot"))]
    if role == "camera":
        # The simulated camera follows the jobs' events too: it empties its workspace while a job
        # takes backgrounds, and logs its truth into each job's recording.
        return [("serve", keys.camera_capture(cell)), ("query", keys.robot_state(cell)),
                ("subscribe", keys.events(cell, "*")), ("announce", keys.alive(cell, "camera"))]
    if role == "reconstruct":
        if worker != "*" and not keys.WORKER_ID.fullmatch(worker):
            raise ValueError(f"reconstruct user {worker!r} is no worker id: its user name must be letters, digits, "
                             f"'.', '_' and '-', starting with a letter or digit")
        return [("serve", keys.reconstructor(worker)), ("serve", keys.reconstructor_info(worker)),
                ("publish", keys.reconstructor_heartbeat(worker)), ("announce", keys.reconstructor_alive(worker))]
    raise ValueError(f"unknown role {role!r}: expected one of {', '.join(ROLES)}")


def _rules(subject: str, grants: Iterable[tuple[str, str]]) -> list[dict[str, object]]:
    """The allow rules of one subject: messages that share a flow and the same keys share a rule."""
    keys_of: dict[tuple[str, str], set[str]] = {}
    for verb, key in grants:
        for flow, message in _MESSAGES[verb]:
            keys_of.setdefault((flow, message), set()).add(key)
    messages_of: dict[tuple[str, tuple[str, ...]], list[str]] = {}
    for (flow, message), key_set in keys_of.items():
        messages_of.setdefault((flow, tuple(sorted(key_set))), []).append(message)
    # A message has one group per flow, so the messages name the rule.
    return [{"id": f"{subject} {flow} {'+'.join(sorted(messages))}", "permission": "allow", "flows": [flow],
             "messages": sorted(messages), "key_exprs": list(key_exprs)}
            for (flow, key_exprs), messages in sorted(messages_of.items())]


def pool_subject(user: str) -> str:
    """The subject of the access control that holds one reconstruct user (``:`` is in no user name)."""
    return f"reconstruct:{user}"


def access_control(users: Mapping[str, Mapping[str, Iterable[str]]]) -> dict[str, object]:
    """The router's ``access_control`` block (JSON, as Zenoh's configuration takes it).

    Parameters
    ----------
    users : cell id -> role -> Zenoh user names
        Who plays which role in which cell. A ``reconstruct`` user serves the pool of
        every cell, whichever cell lists it, under the worker id that is its user name.

    Raises
    ------
    ValueError
        If a role is unknown, a cell id is not one (see ``wire.config``), a user name is empty or
        holds ":", a reconstruct user's name is no worker id, or no user has a role at all (the
        router would refuse everyone).

    >>> block = access_control({"cell1": {"client": ["alice"], "daemon": ["cell1"], "reconstruct": ["r1"]}})
    >>> block["default_permission"], [s["id"] for s in block["subjects"]]
    ('deny', ['client@cell1', 'daemon@cell1', 'reconstruct:r1'])
    """
    subjects: dict[str, set[str]] = {}
    grants: dict[str, list[tuple[str, str]]] = {}
    for cell, roles in users.items():
        if not keys.CELL_ID.fullmatch(cell):
            raise ValueError(f"cell id {cell!r} must be letters, digits, '_' and '-', starting with a letter or digit")
        for role, names in roles.items():
            names = set(names)
            for name in names:
                if not USER_NAME.fullmatch(name):
                    raise ValueError(f"user name {name!r} ({role} in {cell}) must be non-empty, without ':' "
                                     f"or spaces at its ends")
            if role in POOL_ROLES:   # one subject per worker: its rules name its own id
                for name in names:
                    subjects.setdefault(pool_subject(name), set()).add(name)
                    grants[pool_subject(name)] = permissions(role, cell, name)
                continue
            granted = permissions(role, cell)
            if names:
                subjects.setdefault(f"{role}@{cell}", set()).update(names)
                grants[f"{role}@{cell}"] = granted
    if not subjects:
        raise ValueError("no user has a role: the router would refuse every session")
    ordered = sorted(subjects)
    rules = {subject: _rules(subject, grants[subject]) for subject in ordered}
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": [rule for subject in ordered for rule in rules[subject]],
        "subjects": [{"id": subject, "usernames": sorted(subjects[subject])} for subject in ordered],
        "policies": [{"id": subject, "rules": [rule["id"] for rule in rules[subject]], "subjects": [subject]}
                     for subject in ordered],
    }


#: What each part of a cell does under its role, for the one line that says it may not.
PARTS = {"daemon": "run the cell daemon", "robot": "run the robot worker", "camera": "run the camera worker",
         "reconstruct": "run a reconstruction worker"}


def roles_that_may(verb: str, key: str, cell: str) -> list[str]:
    """The roles whose rules let a session ``verb`` (see :func:`permissions`) on ``key`` in ``cell``.

    >>> roles_that_may("query", "robocell/cell1/submit", "cell1")
    ['client']
    >>> roles_that_may("query", "robocell/cell1/jobs/42", "cell1")
    ['client', 'observer']
    """
    import zenoh   # only here: the configuration, which imports this module, is read without Zenoh

    asked = zenoh.KeyExpr(key)
    return [role for role in ROLES
            if any(granted == verb and zenoh.KeyExpr(expr).includes(asked) for granted, expr in permissions(role, cell))]


def what_a_query_asks(key: str, cell: str) -> str:
    """A query on one of the daemon's keys in words: ``"submit jobs"``, ``"cancel jobs"``, ...

    >>> what_a_query_asks("robocell/cell1/jobs/7/cancel", "cell1")
    'cancel jobs'
    """
    parts = key.split("/")
    if key == keys.submit(cell):
        return "submit jobs"
    if key == keys.jobs(cell):
        return "list jobs"
    if key == keys.status(cell):
        return "read the cell's status"
    if len(parts) == 5 and key.startswith(keys.jobs(cell) + "/"):
        return {"cancel": "cancel jobs", "result": "read job results"}.get(parts[4], f"ask {key}")
    if len(parts) == 4 and key.startswith(keys.jobs(cell) + "/"):
        return "read a job's status"
    return f"ask {key}"


def part_refusal(users: Mapping[str, Mapping[str, Iterable[str]]], user: str | None, role: str, cell: str) -> str | None:
    """Why the router's access control, made from ``users`` (cell id -> role -> user names, as
    :func:`access_control` takes them), would drop what a part of ``role`` declares in ``cell``
    as ``user``, unseen: one line; None when it lets the part run, or without access control.

    >>> users = {"cell1": {"robot": ["robot1"], "client": ["alice"]}}
    >>> part_refusal(users, "robot1", "robot", "cell1") is None
    True
    >>> part_refusal(users, "alice", "robot", "cell1")
    "user 'alice' may not run the robot worker of cell cell1: [zenoh.roles] robot is robot1 (alice is client); \
the router's access control would drop its declarations unseen"
    """
    if not users:
        return None
    if role in POOL_ROLES:   # a pool worker serves every cell, whichever cell's table names it
        holders = sorted({name for roles in users.values() for name in roles.get(role, ())})
    else:
        holders = sorted(users.get(cell, {}).get(role, ()))
    if user is not None and user in holders:
        return None
    what = f"{PARTS.get(role, role)}" + ("" if role in POOL_ROLES else f" of cell {cell}")
    if user is None:
        return (f"a session without a user may not {what}: the router's access control ([zenoh.roles]) lets only "
                f"users it names do anything; set [zenoh] user (one of [zenoh.roles] {role}: "
                f"{', '.join(holders) or 'nobody'})")
    has = sorted({r for roles in users.values() for r, names in roles.items() if user in names})
    return (f"user {user!r} may not {what}: [zenoh.roles] {role} is {', '.join(holders) or 'nobody'} "
            f"({user} is {', '.join(has) or 'in no role'}); the router's access control would drop its "
            f"declarations unseen")
