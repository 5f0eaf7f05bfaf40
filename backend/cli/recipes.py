"""``visioncell recipes list | show | create | activate``: the running cell's recipes.

Each command asks the running cell (``--url``, ``--token``) through the REST API, so the
role rules are the API's: a viewer lists and shows, an operator selects the active recipe
(``activate``, a line changeover), only an engineer creates one.  ``activate`` takes the
recipe's id or, with ``--number``, the number a PLC would send.
"""

from __future__ import annotations

import json
from typing import Annotated, Any

import typer

from backend.cli.remote import cell_api, request
from backend.cli.remote import fail as _fail

__all__ = ["recipes_app", "register"]

recipes_app = typer.Typer(help="Recipes: named inspection configurations.", no_args_is_help=True)
POLICIES = ("naive", "top-only", "two-views", "best-next")
BELT_MODES = ("index", "continuous")
_MAX_ID = 2**31 - 1

Token = Annotated[str, typer.Option(help="API token", envvar="VISIONCELL_TOKEN")]
Url = Annotated[str | None, typer.Option(help="Cell URL (default: from the settings)")]


def register(app: typer.Typer) -> None:
    """Add the ``recipes`` command group to the ``visioncell`` app."""
    app.add_typer(recipes_app, name="recipes")


def _line(r: dict[str, Any]) -> str:
    mark = "*" if r.get("active") else " "
    threshold = "auto" if r["threshold"] is None else f"{r['threshold']:.2f}"
    models = ",".join(r["models"]) or "all models"
    belt = r["belt_mode"] or "belt as is"
    return (f"{mark} #{r['id']} no. {r['number']} {r['name']}: {r['policy']}, "
            f"{r['max_views']} view(s), sort {'on' if r['sort'] else 'off'}, threshold "
            f"{threshold}, {belt}, {models}")  # fmt: skip


def _find(base: str, token: str, number: int) -> dict[str, Any]:
    page = request(f"{base}/recipes?limit=1000", token)
    for r in page["data"]:
        if r["number"] == number:
            return r
    raise _fail(f"no recipe numbered {number} in this cell")


@recipes_app.command("list")
def list_recipes(token: Token, url: Url = None) -> None:
    """Print the cell's recipes by number (``*``: the active one)."""
    base = cell_api(url)
    page = request(f"{base}/recipes?limit=1000", token)
    for r in page["data"]:
        print(_line(r))
    active = page.get("active")
    print(f"{page['count']} recipe(s); active: {active['name'] if active else 'none'}")


@recipes_app.command("show")
def show(
    recipe_id: Annotated[int, typer.Argument(help="Recipe id")], token: Token, url: Url = None
) -> None:
    """Print one recipe as JSON."""
    if not 1 <= recipe_id <= _MAX_ID:
        raise _fail(f"a recipe id is in 1..{_MAX_ID}, got {recipe_id}")
    print(json.dumps(request(f"{cell_api(url)}/recipes/{recipe_id}", token), indent=2))


@recipes_app.command("create")
def create(
    name: Annotated[str, typer.Argument(help="Recipe name (a word, unique in the cell)")],
    number: Annotated[int, typer.Option(help="Number a PLC selects it by, 1..9999")],
    token: Token,
    url: Url = None,
    policy: Annotated[str, typer.Option(help=", ".join(POLICIES))] = "two-views",
    max_views: Annotated[int, typer.Option(help="Views at most, 1..3")] = 3,
    sort: Annotated[bool, typer.Option(help="Pick and sort into the bins")] = False,
    threshold: Annotated[
        float | None, typer.Option(help="Fixed score threshold 0..1 (default: automatic)")
    ] = None,
    belt_mode: Annotated[
        str | None, typer.Option(help="index or continuous (default: the belt as it is)")
    ] = None,
    model: Annotated[
        list[str] | None, typer.Option(help="A model in play (repeat; default: every model)")
    ] = None,
    bin: Annotated[
        list[str] | None, typer.Option(help="MODEL=BIN: the bin a model goes to (repeat)")
    ] = None,
    description: Annotated[str, typer.Option(help="Free text")] = "",
    reason: Annotated[str | None, typer.Option(help="Why (audit trail)")] = None,
) -> None:
    """Create a recipe (engineer token) and print it."""
    if not 1 <= number <= 9999:
        raise _fail(f"--number must be in 1..9999, got {number}")
    if policy not in POLICIES:
        raise _fail(f"--policy must be one of {', '.join(POLICIES)}, got {policy!r}")
    if belt_mode is not None and belt_mode not in BELT_MODES:
        raise _fail(f"--belt-mode must be index or continuous, got {belt_mode!r}")
    bins: dict[str, str] = {}
    for pair in bin or []:
        m, sep, b = pair.partition("=")
        if not sep or not m or not b:
            raise _fail(f"--bin takes MODEL=BIN, got {pair!r}")
        bins[m] = b
    body = {"name": name, "number": number, "policy": policy, "max_views": max_views,
            "sort": sort, "threshold": threshold, "belt_mode": belt_mode,
            "models": list(model or []), "bins": bins, "description": description,
            "reason": reason}  # fmt: skip
    print(_line(request(f"{cell_api(url)}/recipes", token, "POST", body)))


@recipes_app.command("activate")
def activate(
    token: Token,
    recipe_id: Annotated[int | None, typer.Argument(help="Recipe id")] = None,
    number: Annotated[int | None, typer.Option(help="Select by the recipe's number")] = None,
    url: Url = None,
    reason: Annotated[str | None, typer.Option(help="Why (audit trail)")] = None,
) -> None:
    """Make a recipe the cell's active one (operator token); runs take it from their next
    object."""
    base = cell_api(url)
    if (recipe_id is None) == (number is None):
        raise _fail("give a recipe id or --number, one of the two")
    if number is not None:
        if not 1 <= number <= 9999:
            raise _fail(f"--number must be in 1..9999, got {number}")
        recipe_id = _find(base, token, number)["id"]
    assert recipe_id is not None
    if not 1 <= recipe_id <= _MAX_ID:
        raise _fail(f"a recipe id is in 1..{_MAX_ID}, got {recipe_id}")
    r = request(f"{base}/recipes/{recipe_id}/activate", token, "POST", {"reason": reason})
    print(f"active: {_line(r).lstrip('* ')}")
