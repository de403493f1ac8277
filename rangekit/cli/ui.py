"""rangekit ui: a local web app onto the rig (live camera, test patterns, turntable, device status)."""

from __future__ import annotations

import argparse
import ipaddress
import sys
from pathlib import Path

from rangekit.cli._common import say
from rangekit.errors import UsageError


#: The simulated rig's rig file in the sessions folder: the camera controls the app sets are written there.
SIM_RIG_FILE = "sim-rig.json"


def _port(text: str) -> int:
    try:
        port = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a port number 0-65535, found {text!r}") from None
    if not 0 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"expected a port number 0-65535, found {port}")
    return port


def _is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def cmd_ui(args: argparse.Namespace) -> int:
    """rangekit ui [--rig sim|RIG.json] [--sessions DIR] [--port 8765] [--host 127.0.0.1]"""
    from rangekit.ui.rig_holder import RigHolder
    from rangekit.ui.server import bind, serve, start

    hardware = args.rig not in (None, "sim")
    if hardware and args.object is not None:
        raise UsageError("--object: a simulator option; leave it out with --rig RIG.json")
    sessions = Path(args.sessions or ".")
    if not sessions.is_dir():
        raise UsageError(f"--sessions {sessions}: not a folder; create it first or name another")
    rig_file = Path(args.rig) if hardware else sessions / SIM_RIG_FILE
    sock = bind(args.host, args.port)       # a port in use is said before anything is opened or written
    try:
        # A hardware rig file that fails its checks ends here with its one-line error; a device that does not
        # open is shown on the page (and retried from there).
        holder = RigHolder.hardware(rig_file) if hardware else RigHolder.simulated(rig_file, args.object or "lumpy")
        server = start(holder, sock, args.host, sessions, args.object or "lumpy")
    except BaseException:
        sock.close()
        raise
    if not _is_loopback(args.host):
        print(f"rangekit ui: warning: listening on {args.host}, not loopback: anyone who can reach it and has "
              "the URL's token can drive the rig", file=sys.stderr)
    what = f"the rig file {rig_file}" if hardware else f"the simulated rig (rig file {rig_file})"
    say(f"rangekit ui on {server.host}:{server.port}, {what}; open in a browser:")
    if holder.fault:
        print(f"rangekit ui: warning: {holder.fault}", file=sys.stderr)
    print(server.url, flush=True)
    try:
        serve(server, sock)
    finally:
        sock.close()
    return 0


def add_parsers(sub) -> None:
    p = sub.add_parser("ui", help="a local web app: the live camera, test patterns, the turntable, device status",
                       description="Start a local web server and print its URL with a one-time token (open it in "
                                   "a browser). It binds 127.0.0.1 unless --host says otherwise; every API request "
                                   "needs the token (the page sends it in a header, never a cookie), and changes "
                                   "and WebSockets only come from the app's own page.")
    p.add_argument("--rig", help="'sim' (default): the simulated rig; or a rig file whose 'devices' name the camera, "
                                 "projector and turntable (rangekit rig init writes a template)")
    p.add_argument("--object", help="the simulated object on the turntable (default lumpy; 'shiny' saturates)")
    p.add_argument("--sessions", help="folder of the sessions the app lists and writes (default: the current one); the simulated "
                                        f"rig's rig file is {SIM_RIG_FILE} there")
    p.add_argument("--port", type=_port, default=8765, help="TCP port (default 8765; 0: any free one)")
    p.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1: this machine only)")
    p.set_defaults(func=cmd_ui)
