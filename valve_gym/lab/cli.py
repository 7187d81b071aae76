"""``valve-gym lab [--port N] [--no-browser] [--address HOST]``: serve the teaching lab.

Serves :func:`valve_gym.lab.build_app` with Panel (Bokeh server) on
``localhost:N`` (default 5006) and opens the browser unless ``--no-browser``.
``--address 0.0.0.0`` serves a classroom: every interface, and websocket
connections from any origin are accepted. Stop it with Ctrl-C.
"""
from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

__all__ = ["main", "serve"]


def serve(port: int = 5006, address: str = "localhost", show: bool = True, threaded: bool = False, **kw):
    """Serve the lab; returns Panel's server object (``threaded=True``: a stoppable thread).

    Parameters
    ----------
    port : int
        TCP port (0: any free port).
    address : str
        Interface to listen on (``"0.0.0.0"``: every interface, any websocket origin allowed).
    show : bool
        Open the browser.
    threaded : bool
        Run the server in a background thread (tests) instead of blocking.
    """
    from ._need import need_panel

    need_panel()
    import panel as pn

    from .app import build_app

    if address in ("0.0.0.0", "::") or port == 0:   # a classroom server; or a port not known yet (local)
        origin = ["*"]
    else:
        origin = sorted({f"localhost:{port}", f"127.0.0.1:{port}", f"{address}:{port}"})
    return pn.serve({"lab": build_app}, port=port, address=address, show=show, threaded=threaded,
                    websocket_origin=origin, title="valve_gym teaching lab", **kw)


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``valve-gym lab``; returns the exit status (2 on bad arguments, 1 without Panel)."""
    ap = argparse.ArgumentParser(
        prog="valve-gym lab",
        description="Serve the teaching lab (valve, loop and compensator pages) in the browser.")
    ap.add_argument("--port", type=int, default=5006, metavar="N", help="TCP port (default 5006; 0: any free port)")
    ap.add_argument("--no-browser", action="store_true", help="do not open a browser")
    ap.add_argument("--address", default="localhost", metavar="HOST",
                    help="interface to listen on (default localhost; 0.0.0.0 for a classroom server, "
                         "which accepts websocket connections from any origin)")
    args = ap.parse_args(None if argv is None else list(argv))
    if not 0 <= args.port <= 65535:
        ap.error(f"--port must be between 0 and 65535, got {args.port}")
    from ._need import MISSING

    try:
        from ._need import need_panel

        need_panel()
    except ImportError:
        print(f"valve-gym lab: {MISSING}", file=sys.stderr)
        return 1
    host = "localhost" if args.address in ("0.0.0.0", "::") else args.address
    print(f"valve-gym lab: serving on http://{host}:{args.port}/lab (Ctrl-C stops)", flush=True)
    try:
        serve(port=args.port, address=args.address, show=not args.no_browser)
    except OSError as exc:
        print(f"valve-gym lab: cannot listen on {args.address}:{args.port}: {exc}; choose another --port",
              file=sys.stderr)
        return 1
    return 0
