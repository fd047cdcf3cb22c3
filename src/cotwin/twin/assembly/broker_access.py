"""Least-privilege RabbitMQ accounts for a twin project: one user per role, each allowed to configure,
write and read only the exchanges and queues that role uses (RabbitMQ matches each permission as a
regular expression against the resource's name), and, on the twin's topic exchange, only the routing
keys it publishes or binds (topic permissions). See docs/security.md.

What each role touches (E: the command exchange, A: the twin's topic exchange for alarms and what-if
requests, R: a robot request queue):
- twin: declares E and its own `cotwin.E.*` command queue (binds it to E: read E, write the queue),
  publishes echoes to E and alarms to A, declares broker-named queues (`amq.gen-*`): the robot link's
  reply queue and the what-if service's request queue (bound to A), publishes robot requests and
  what-if answers through the default exchange (`amq.default`);
- robot: declares R (exclusive), consumes it, answers through `amq.default`;
- publisher: declares E and its own `amq.gen-*` queue bound to E, publishes commands to E;
- monitor: reads the alarms: its own `amq.gen-*` queue bound to A; publishes nothing;
- whatif: publishes what-if requests to A (routing keys `twin.whatif[.*]` only) and reads the answers
  on its own `amq.gen-*` queue.
"""

from __future__ import annotations

import shlex
from dataclasses import dataclass

from ..project import TwinProject

_SPECIAL = set("\\.^$|?*+()[]{}")
WHATIF_KEY = "twin.whatif"  # twin.whatif.WhatIfService's routing key


def escape(name: str) -> str:
    """A resource name as a regular expression matching only itself."""
    return "".join("\\" + c if c in _SPECIAL else c for c in name)


def _only(*patterns: str) -> str:
    return f"^{patterns[0]}$" if len(patterns) == 1 else "^(" + "|".join(patterns) + ")$"


@dataclass(frozen=True)
class Role:
    name: str  # twin | robot | publisher | monitor | whatif
    user: str
    configure: str
    write: str
    read: str
    topic: tuple[str, str, str] | None = None  # (topic exchange, routing keys it may publish, ... bind)


def roles(project: TwinProject, prefix: str = "cotwin-") -> list[Role]:
    """The accounts a project needs, with their permissions (users named `prefix` + role)."""
    commands = project.rabbitmq.exchange if project.rabbitmq else "fmi_digital_twin_dt"
    alarms = project.deviation.exchange
    robots = sorted({project.queue, *([project.pt.queue] if project.pt and project.pt.endpoint == "broker" else [])})
    e, a, gen = escape(commands), escape(alarms), r"amq\.gen-.*"
    bridge = escape(f"cotwin.{commands}.") + ".*"
    r = [escape(q) for q in robots]
    whatif_keys = _only(escape(WHATIF_KEY) + r"(\..*)?")
    nothing = "^$"
    return [
        Role("twin", prefix + "twin", _only(e, bridge, a, gen), _only(e, bridge, a, gen, r"amq\.default"),
             _only(e, bridge, a, gen), (alarms, _only(escape(project.deviation.routing_key)), whatif_keys)),
        Role("robot", prefix + "robot", _only(*r), _only(r"amq\.default"), _only(*r)),
        Role("publisher", prefix + "publisher", _only(e, gen), _only(e, gen), _only(e, gen)),
        Role("monitor", prefix + "monitor", _only(gen), _only(gen), _only(a, gen), (alarms, nothing, ".*")),
        Role("whatif", prefix + "whatif", _only(gen), _only(a), _only(gen), (alarms, whatif_keys, nothing)),
    ]


def rabbitmqctl_script(project: TwinProject, vhost: str = "cotwin", prefix: str = "cotwin-") -> str:
    """The rabbitmqctl commands creating the vhost and the role accounts (passwords read from stdin)."""
    q = shlex.quote
    lines = [f"rabbitmqctl add_vhost {q(vhost)}"]
    for role in roles(project, prefix):
        lines += [f"# {role.name}",
                  f"rabbitmqctl add_user {q(role.user)}    # type its password (read from standard input)",
                  f"rabbitmqctl set_permissions -p {q(vhost)} {q(role.user)} {q(role.configure)} {q(role.write)} {q(role.read)}"]
        if role.topic is not None:
            exchange, write, read = role.topic
            lines.append(f"rabbitmqctl set_topic_permissions -p {q(vhost)} {q(role.user)} {q(exchange)} {q(write)} {q(read)}")
    return "\n".join(lines) + "\n"
