"""MkDocs hooks (``hooks:`` in mkdocs.yml): the family pages' feature tables are generated from the
feature declarations at every build, so they cannot drift from the code.

A page writes ``<!-- contextrl:features FAMILY -->`` on a line of its own; the build replaces it with one
section per environment of that family (``crl.spec(id).family``): its one-line description, gymnasium
id, CARL name, spaces and time limit, the feature table (default, bounds, unit, what the feature
affects, meaning, the aliases: CARL's and the paper's names) and the coherence rules its contexts must
satisfy, and the environment's animation when ``docs/images/<Id>.gif`` exists (``make docs-gifs`` renders
them; see tools/render_docs_gifs.py). ``<!-- contextrl:environments -->`` becomes the summary table of every registered environment.
The same functions write ``docs/environments.md`` (``contextrl docs --out docs/environments.md``).

``<!-- contextrl:config MODULE.CLASS -->`` becomes a table of a config dataclass: each field, its
default and the docstring written under it in the source, so the agents page lists every
hyper-parameter as the code declares it. On the rendered pages, Sphinx roles in docstrings
(:func:`sample`) are shown as plain code.
"""

from __future__ import annotations

import ast
import dataclasses
import importlib
import importlib.util
import inspect
import posixpath
import re
import textwrap
from pathlib import Path

# Docstrings cross-reference with Sphinx roles (:func:`sample`); the API pages show just the code.
SPHINX_ROLE = re.compile(r":(?:py:)?(?:class|func|meth|attr|mod|data|exc|obj):(?=<code>)")
MARKER = re.compile(r"^<!-- contextrl:(features|environments|config)(?: ([\w.]+))? -->$", re.M)


DOCS = Path(__file__).resolve().parents[1] / "docs"


def gif_grids() -> dict[str, tuple[str, int]]:
    """The ``contextrl render --grid`` of each GIF that tools/render_docs_gifs.py renders."""
    path = Path(__file__).with_name("render_docs_gifs.py")
    spec = importlib.util.spec_from_file_location("render_docs_gifs", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.GIFS


def family_markdown(family: str, page_dir: str = "families") -> str:
    """One section per registered environment of ``family``, from the declarations; image links are
    relative to ``page_dir``, the folder of the page under docs/."""
    import contextrl as crl
    from contextrl.cli import _space_label, feature_rows, markdown_table

    ids = [env_id for env_id in crl.registered() if crl.spec(env_id).family == family]
    if not ids:
        raise ValueError(f"no registered environment has the family {family!r}")
    parts, grids = [], gif_grids()
    for env_id in ids:
        env_spec = crl.spec(env_id)
        env = env_spec.factory()
        description = (type(env).__doc__ or "").strip().splitlines()[0]
        carl = ", ".join(f"`{alias}`" for alias in env_spec.aliases) or "none"
        parts += [
            f"### {env_id}",
            "",
            description,
            "",
            f"gymnasium id `contextrl/{env_id}-v0` · CARL name {carl} · "
            f"{'host' if env_spec.host else 'JAX'} · action {_space_label(env.action_space)} · "
            f"observation {_space_label(env.base_observation_space)} · "
            f"time limit {env.default_max_steps} steps",
            "",
        ]
        if (DOCS / "images" / f"{env_id}.gif").exists() and env_id in grids:
            source = posixpath.relpath(f"images/{env_id}.gif", page_dir)
            grid, steps = grids[env_id]
            caption = f"{env_id}, {steps} random steps under {grid.replace(',', ', ')}"
            parts += [
                f"![{caption}]({source})",
                "",
                f"*`contextrl render {env_id} --grid {grid}`*",
                "",
            ]
        parts += [markdown_table(feature_rows(env.context_space)), ""]
        if env.left_out:
            parts += ["Not offered (they cannot act here):", ""]
            parts += [f"- `{name}`: {why}" for name, why in env.left_out.items()]
            parts += [""]
        if env.context_space.rules:
            parts += ["Contexts must also satisfy (checked on every context and every spec):", ""]
            parts += [f"- `{rule.requirement}`: {rule.why}" for rule in env.context_space.rules]
            parts.append("")
        close = getattr(env, "close", None)
        if env_spec.host and close is not None:
            close()
    return "\n".join(parts)


def environments_table() -> str:
    from contextrl.cli import environment_rows, markdown_table

    return markdown_table(environment_rows())


def field_docstrings(cls: type) -> dict[str, str]:
    """The string literal written under each annotated field of ``cls``'s class body or, for a field
    it inherits or only gives a new default, of its nearest dataclass base."""
    docs = {}
    for klass in reversed([k for k in cls.__mro__ if dataclasses.is_dataclass(k)]):
        body = ast.parse(textwrap.dedent(inspect.getsource(klass))).body[0].body
        for statement, following in zip(body, body[1:], strict=False):
            if (
                isinstance(statement, ast.AnnAssign)
                and isinstance(statement.target, ast.Name)
                and isinstance(following, ast.Expr)
                and isinstance(following.value, ast.Constant)
                and isinstance(following.value.value, str)
            ):
                docs[statement.target.id] = " ".join(following.value.value.split())
    return docs


def config_table(path: str) -> str:
    """A Markdown table of the config dataclass at ``module.Class``: field, default, meaning."""
    from contextrl.cli import markdown_table

    module, _, name = path.rpartition(".")
    cls = getattr(importlib.import_module(module), name)
    docs = field_docstrings(cls)
    rows = []
    for field in dataclasses.fields(cls):
        if field.default is not dataclasses.MISSING:
            default = f"`{field.default!r}`"
        elif field.default_factory is not dataclasses.MISSING:
            default = f"`{field.default_factory()!r}`"
        else:
            default = "(required)"
        rows.append(
            {"field": f"`{field.name}`", "default": default, "meaning": docs.get(field.name, "")}
        )
    missing = [row["field"] for row in rows if not row["meaning"]]
    if missing:
        raise ValueError(f"{path}: fields without a docstring: {', '.join(missing)}")
    return markdown_table(rows)


def on_page_markdown(markdown: str, page, config, files) -> str:
    def replace(match: re.Match) -> str:
        if match.group(1) == "environments":
            return environments_table()
        if match.group(1) == "config":
            return config_table(match.group(2))
        return family_markdown(match.group(2), posixpath.dirname(page.file.src_uri))

    return MARKER.sub(replace, markdown)


def on_page_content(html: str, page, config, files) -> str:
    return SPHINX_ROLE.sub("", html)
