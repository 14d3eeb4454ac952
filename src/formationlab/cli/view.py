"""Command ``view``: watch, drag and tune a scenario live in the browser, or replay a run."""

from __future__ import annotations

import ipaddress
from pathlib import Path
from typing import Annotated

import typer

from ..errors import UserInputError
from ._app import command, err_console

__all__: list[str] = []


@command(
    "view",
    epilog=(
        "Examples:  formationlab view examples/paper-simulation-2.toml\n\n"
        "           formationlab view runs/sim2   (replay a run folder with a time slider)\n\n"
        "           formationlab view examples/space/tetrahedron-mirror.toml   (in 3-D)"
    ),
)
def view(
    target: Annotated[
        Path, typer.Argument(help="Scenario file (TOML), or a `run` output folder to replay.")
    ],
    replay: Annotated[
        Path | None, typer.Option("--replay", help="Replay this `run` output folder.")
    ] = None,
    port: Annotated[int, typer.Option(min=0, max=65535, help="Port (0: a free one).")] = 0,
    host: Annotated[
        str, typer.Option(help="Address to bind; anything but loopback exposes the run.")
    ] = "127.0.0.1",
    no_browser: Annotated[
        bool, typer.Option("--no-browser", help="Print the URL, do not open a browser.")
    ] = False,
    seed: Annotated[int | None, typer.Option(help="Seed of the random perturbations.")] = None,
) -> None:
    """Serve an interactive view of a scenario on a local web page and open it.

    The simulation runs here and streams to the page at the display's rate.
    On the page: drag robots, pause, step, reset, change the speed, the law
    and its gains (k_c, k_a, theta), the integrator and dt, perturb the robots,
    download the state as a scenario (TOML) or a PNG. Given the folder of
    `formationlab run`, it replays the run with a time slider. A formation in space is
    shown in 3-D: orbit (drag), zoom (wheel), pan (right drag), and drag a robot in the
    plane facing the camera. The URL holds a
    random token; the server writes no files. Stop it with Ctrl-C. Needs
    `pip install formationlab[view]`.
    """
    try:
        from ..viewer.controller import Controller
        from ..viewer.server import bind, make_app, make_token, uvicorn_server
    except ModuleNotFoundError as exc:
        if (exc.name or "").startswith("formationlab"):
            raise
        raise UserInputError(
            f"the viewer needs the 'view' extra ({exc.name} is missing); "
            "install it with: pip install 'formationlab[view]'"
        ) from None
    try:
        loopback = ipaddress.ip_address(host).is_loopback
    except ValueError:
        raise UserInputError(
            f"--host must be an IP address such as 127.0.0.1, got {host!r}"
        ) from None
    from ..viewer.sources import open_session

    session = open_session(
        replay if replay is not None else target, replay=replay is not None, seed=seed
    )
    for w in getattr(getattr(session, "scenario", None), "warnings", ()):
        err_console.print(f"[bold yellow]warning:[/] {w}", highlight=False, soft_wrap=True)
    token = make_token()
    try:
        sock = bind(host, port)
    except OSError as exc:
        raise UserInputError(
            f"cannot listen on {host}:{port}: {exc.strerror}; try --port 0"
        ) from None
    bound_port = sock.getsockname()[1]
    shown = f"[{host}]" if ":" in host else host
    url = f"http://{shown}:{bound_port}/?token={token}"
    if not loopback:
        err_console.print(
            f"[bold yellow]warning:[/] listening on {host}: anyone who can reach it and has the "
            "URL can steer the run",
            highlight=False,
        )
    for note in session.info().get("notices", []):
        err_console.print(f"note: {note}", highlight=False, soft_wrap=True)
    typer.echo(f"formationlab view: {url}  (Ctrl-C to stop)")
    if not no_browser:
        import webbrowser

        webbrowser.open(url)
    server = uvicorn_server(make_app(Controller(session), token))
    server.run(sockets=[sock])
