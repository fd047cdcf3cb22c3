"""The `cotwin cache` command: where cotwin's cache is, what it holds, and clearing it (cotwin.cache)."""

from __future__ import annotations

import click

from .common import main


@main.command("cache")
@click.option("--clear", is_flag=True,
              help="remove cotwin's entries from the cache (not those a running process is using; refused when the "
                   "folder holds files cotwin did not write)")
def cache_command(clear: bool) -> None:
    """Show where cotwin's cache is ($COTWIN_CACHE, else ~/.cache/cotwin), its size and entries per kind."""
    from .. import cache

    root = cache.located(off_ok=not clear)
    if root is None:
        click.echo("no cache: COTWIN_CACHE=off (every build compiles and extracts anew)")
        return
    cap, problem = cache.read_cap()
    if problem:
        click.echo(f"warning: {problem}", err=True)
    if clear:
        done = cache.clear(root)
        freed = sum(e.size for e in done.removed)
        click.echo(f"{root}: removed {len(done.removed)} entr{'y' if len(done.removed) == 1 else 'ies'} "
                   f"({cache.size_text(freed)})")
        if done.kept:
            click.echo(f"kept {len(done.kept)} in use by a running cotwin (or being written): "
                       f"{', '.join(sorted({e.kind.folder for e in done.kept}))}")
        return
    try:
        found = cache.contents(root)
    except OSError as err:
        raise cache.refusal(root, f"cannot read the cache: {err.strerror or err}") from None
    state = "" if root.is_dir() else " (not made yet)"
    click.echo(f"{root}{state}: {cache.size_text(found.size)}, at most {cache.size_text(cap)} (COTWIN_CACHE_MAX_MB)")
    for kind in cache.KINDS:
        entries = found.of(kind)
        whole = sum(not e.partial and not e.path.name.endswith(".lock") for e in entries)
        partial = sum(e.partial for e in entries)
        click.echo(f"  {kind.folder + '/':<10} {whole:>5} {kind.what:<26} {cache.size_text(sum(e.size for e in entries)):>10}"
                   + (f"  ({partial} partial)" if partial else ""))
    click.echo("the least recently used of " + ", ".join(k.folder + "/" for k in cache.KINDS if k.rebuildable)
               + " are removed when over the cap (rebuilt when needed)")
    if found.foreign:
        names = ", ".join(str(p.relative_to(root)) for p in found.foreign[:3]) + (", ..." if len(found.foreign) > 3 else "")
        click.echo(f"  also {len(found.foreign)} file(s) cotwin did not write, not counted ({names}): "
                   "--clear refuses here")
