"""Who may use the dashboard: dashboard-access add|remove|list (the access file of --dashboard-access)."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from .common import main

MIN_PASSWORD = 10  # characters


@main.group("dashboard-access")
def dashboard_access() -> None:
    """Viewers and operators of the dashboard, in an access file (see docs/security.md)."""


def _people(path: str) -> list:
    from ..twin.services.dashboard.access import read_access

    return read_access(path) if Path(path).exists() else []


@dashboard_access.command("add")
@click.argument("file", type=click.Path(dir_okay=False))
@click.argument("name")
@click.option("--role", type=click.Choice(["viewer", "operator"]), required=True,
              help="viewers see the page; operators also command the robot and run what-ifs")
@click.option("--token", is_flag=True, help="generate a token (printed once) instead of asking for a password")
def add(file: str, name: str, role: str, token: bool) -> None:
    """Let NAME use the dashboard as ROLE, with a password (asked for, or one line on standard input) or a
    generated token; replaces NAME's line if there is one. The file is created with mode 600."""
    from ..twin.services.dashboard.access import NAME, Person, hash_password, hash_token, new_token, write_access

    if not NAME.match(name):
        raise click.BadParameter(f"{name[:40]!r} is not a name (letters, digits, . _ @ + -, at most 64)",
                                 param_hint="NAME")
    people = [p for p in _people(file) if p.name != name]
    replaced = len(people) != len(_people(file))
    if token:
        secret = new_token()
        stored = hash_token(secret)
    else:
        if sys.stdin.isatty():
            secret = click.prompt(f"password for {name}", hide_input=True, confirmation_prompt=True)
        else:
            secret = sys.stdin.readline().rstrip("\r\n")
        if len(secret) < MIN_PASSWORD:
            raise click.UsageError(f"a password of at least {MIN_PASSWORD} characters (or --token)")
        stored = hash_password(secret)
    write_access(file, [*people, Person(name, role, stored)])
    click.echo(f"{'replaced' if replaced else 'added'} {name} ({role}) in {file}", err=True)
    if token:
        click.echo(f"token for {name} (shown once: send it as 'Authorization: Bearer TOKEN', or log in with it):",
                   err=True)
        click.echo(secret)


@dashboard_access.command("remove")
@click.argument("file", type=click.Path(dir_okay=False))
@click.argument("name")
def remove(file: str, name: str) -> None:
    """Take NAME's access away (a running dashboard notices within a second, and ends NAME's sessions)."""
    from ..twin.services.dashboard.access import write_access

    people = _people(file)
    kept = [p for p in people if p.name != name]
    if len(kept) == len(people):
        raise click.BadParameter(f"no {name[:40]!r} in {file}", param_hint="NAME")
    write_access(file, kept)
    click.echo(f"removed {name} from {file}", err=True)


@dashboard_access.command("list")
@click.argument("file", type=click.Path(dir_okay=False, exists=True))
def list_people(file: str) -> None:
    """Who may use the dashboard, with their role and how they log in."""
    for person in _people(file):
        click.echo(f"{person.role:<8} {person.name}  ({'token' if person.secret.startswith('sha256:') else 'password'})")
