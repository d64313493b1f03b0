"""The monitor's web server (aiohttp): one page, one websocket of updates, and (if enabled) page commands.

aiohttp: one well-kept asyncio package that is both the HTTP server and the websocket end, so the monitor
needs no separate ASGI server and no framework; the page is plain HTML + JavaScript shipped in the package.
"""

from __future__ import annotations

import asyncio
import errno
import json
import math
from importlib import resources
from typing import TYPE_CHECKING, Any

import numpy as np

from antarium import bus
from antarium.monitor.hub import Hub
from antarium.monitor.settings import PAGE_COMMANDS, allowed, foreign_host, refused_params, served_names

if TYPE_CHECKING:
    from antarium.config import MonitorSection

#: LED frames sent to a page and not yet drawn there, at most
IN_FLIGHT = 2
#: side of the equal-area map (CSS pixels)
MAP_SIZE = 560


def dome_geometry() -> dict[str, Any]:
    """LED positions for the page: equal-area map pixels (seen from above, +x right, +y up) and the map's scale
    (pixels per unit Lambert radius: the 3D view looks its fragments' directions up in the map), 3D directions,
    UV flags and the 55 panels' corners (unit sphere)."""
    from antarium.geometry import load_dome

    dome = load_dome()
    d = np.asarray(dome.directions)
    scale = (MAP_SIZE / 2 - 4) / _lambert(d).max()

    def to_map(v: np.ndarray) -> np.ndarray:  # unit vectors (n, 3) -> map pixels (n, 2), +y down
        r, az = _lambert(v), np.arctan2(v[:, 1], v[:, 0])
        return np.stack([MAP_SIZE / 2 + scale * r * np.cos(az), MAP_SIZE / 2 - scale * r * np.sin(az)], axis=1)

    px, py = np.round(to_map(d)).astype(int).T
    # a UV pixel's panel x and y axes on the map (pixels per radian): polariser bars are drawn along
    # cos(angle) * ax + sin(angle) * ay
    uv = np.asarray(dome.uv_index)
    axes = np.asarray(dome.panel_axes)[np.asarray(dome.panel)[uv]]
    step = 1e-3
    on_map = [(to_map(_unit(d[uv] + step * axes[:, k])) - to_map(d[uv])) / step for k in (0, 1)]
    corners = np.asarray(dome.panel_corners)
    corners = corners / np.linalg.norm(corners, axis=-1, keepdims=True)
    return {"size": MAP_SIZE, "scale": float(scale), "x": px.tolist(), "y": py.tolist(),
            "uv": np.asarray(dome.is_uv).astype(int).tolist(),
            "dirs": np.round(d, 4).ravel().tolist(), "panels": np.round(corners, 4).ravel().tolist(),
            "uv_index": uv.tolist(), "uv_ax": np.round(on_map[0], 2).ravel().tolist(),
            "uv_ay": np.round(on_map[1], 2).ravel().tolist()}


def _lambert(v: np.ndarray) -> np.ndarray:
    """Radius of unit vectors (n, 3) in the Lambert azimuthal equal-area map about the zenith (0..2)."""
    return 2.0 * np.sin(np.arccos(np.clip(v[:, 2], -1.0, 1.0)) / 2.0)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=1, keepdims=True)


#: most object points sent for the path view's world map
WORLD_POINTS = 12000


def world_top_view(scene: str) -> dict[str, Any]:
    """{"scene", "points": [x, y, ...] (m, world frame, at most WORLD_POINTS objects' vertices above the ground)}
    or {"scene", "error"} when the scene cannot be built here."""
    from antarium.plots.ant import scene_top_view
    from antarium.renderers import build_scene

    try:
        spec = json.loads(scene) if scene.startswith("{") else scene
        top = scene_top_view(build_scene(spec))
    except Exception as exc:  # noqa: BLE001 - a file only the server can read, a bad spec: the path stays on grid
        return {"scene": scene, "error": f"no top view of {scene!r}: {exc}", "points": []}
    if len(top) > WORLD_POINTS:
        top = top[np.random.default_rng(0).choice(len(top), WORLD_POINTS, replace=False)]
    return {"scene": scene, "points": np.round(top[:, :2], 3).ravel().tolist()}


#: scenes whose top views the monitor keeps (each up to WORLD_POINTS points, about 1 MB): a script that loads a
#: scene of new parameters for each trial (a new scene name each time) would otherwise grow the monitor without end
WORLDS_KEPT = 4


class TopViews:
    """`world_top_view` of the `kept` scenes asked for last, each built once (in a worker thread) while kept."""

    def __init__(self, kept: int = WORLDS_KEPT) -> None:
        self.kept = kept
        self._views: dict[str, dict[str, Any]] = {}  # oldest first

    @property
    def names(self) -> list[str]:
        """The scenes kept, the one asked for last at the end."""
        return list(self._views)

    async def get(self, scene: str) -> dict[str, Any]:
        view = self._views.pop(scene, None)
        if view is None:
            view = await asyncio.get_running_loop().run_in_executor(None, world_top_view, scene)
            self._views.pop(scene, None)  # built meanwhile for another page
        self._views[scene] = view
        while len(self._views) > self.kept:
            del self._views[next(iter(self._views))]
        return view


def refusal(address: str | None, rig: str, allow: list[str]) -> str:
    return (f"antarium monitor: the address {address} may not open the monitor of rig {rig!r}; allowed: "
            f"{', '.join(allow)} ([monitor] allow in the rig config)")


def foreign_origin(origin: str | None, own: str) -> str | None:
    """Why a request named an origin other than the monitor's own `own` ("http://host:port"), or None. Access goes
    by address, so a page of another site open in an allowed browser could reach the monitor too: browsers name
    that page's origin on a POST and a websocket, and send it JSON only after a CORS check this server never passes."""
    if origin is not None and origin != own:
        return f"a page from {origin} may not use the monitor; only its own page ({own}) may"
    return None


def make_app(session, rig: str, settings: MonitorSection):
    """The aiohttp application for rig `rig` on an open zenoh client `session`."""
    from aiohttp import WSMsgType, web

    hub = Hub(session, rig)
    geometry = json.dumps(dome_geometry())
    page = resources.files("antarium.monitor").joinpath("page.html").read_text()
    clients: dict = {}  # websocket -> LED frames it may still be sent before it says "drawn"
    period = 1.0 / settings.update_hz
    # the names the page may be opened by: the Origin check below compares with the Host header, so that header
    # must name this monitor (else a name of an attacker's, pointed at this computer, passes both: DNS rebinding)
    names = served_names(settings.host, settings.hosts)

    @web.middleware
    async def access(request, handler):
        if not allowed(request.remote, settings.allow):
            return web.Response(status=403, text=refusal(request.remote, rig, settings.allow))
        wrong_name = foreign_host(request.headers.get("Host"), names)
        if wrong_name:
            return web.Response(status=403, text=f"antarium monitor: {wrong_name}")
        return await handler(request)

    async def index(request):
        return web.Response(text=page, content_type="text/html")

    async def geometry_json(request):
        return web.Response(text=geometry, content_type="application/json")

    async def websocket(request):
        # not compressed: deflating an LED frame (to 65 %) took the monitor 2 ms of the rig's CPU (docs/monitor.md)
        refused = foreign_origin(request.headers.get("Origin"), f"{request.scheme}://{request.host}")
        if refused:
            return web.Response(status=403, text=f"antarium monitor: {refused}")
        ws = web.WebSocketResponse(max_msg_size=1 << 22, compress=False)
        await ws.prepare(request)
        await ws.send_str(json.dumps({"type": "hello", "rig": rig, "commands": settings.commands,
                                      "page_commands": list(PAGE_COMMANDS)}))
        clients[ws] = IN_FLIGHT
        try:
            async for msg in ws:
                if msg.type == WSMsgType.ERROR:
                    break
                if msg.type == WSMsgType.TEXT and msg.data == "drawn":  # the page is done with one LED frame
                    clients[ws] = min(IN_FLIGHT, clients[ws] + 1)
        finally:
            clients.pop(ws, None)
        return ws

    worlds = TopViews()

    async def world_json(request):
        """The current scene's objects seen from above (for the path view), built once per scene name."""
        name = (hub.status or {}).get("scene")
        if not isinstance(name, str):  # none loaded (or a status of another shape)
            return web.json_response({"scene": None, "points": []})
        return web.json_response(await worlds.get(name))

    async def command(request):
        name = request.match_info["name"]
        if not settings.commands:
            return web.json_response({"error": f"commands from the page are off for rig {rig!r} "
                                      "([monitor] commands = false); use the bus"}, status=403)
        if name not in PAGE_COMMANDS:
            return web.json_response({"error": f"{name!r} cannot be sent from the page; allowed: "
                                      f"{', '.join(PAGE_COMMANDS)}"}, status=400)
        refused = foreign_origin(request.headers.get("Origin"), f"{request.scheme}://{request.host}")
        if refused:
            return web.json_response({"error": f"{name}: {refused}"}, status=403)
        if request.content_type != "application/json":
            return web.json_response({"error": f"{name}: commands are sent as JSON (Content-Type: application/json), "
                                      f"got {request.content_type!r}"}, status=415)
        try:
            params = await request.json() if request.can_read_body else {}
        except ValueError as exc:
            return web.json_response({"error": f"{name}: the body is not JSON: {exc}"}, status=400)
        if not isinstance(params, dict):
            return web.json_response({"error": f"{name}: parameters must be a JSON object"}, status=400)
        refused = refused_params(name, params)
        if refused:
            return web.json_response({"error": refused}, status=400)
        ok, body = await asyncio.get_running_loop().run_in_executor(None, _call, session, rig, name, params)
        return web.json_response(body, status=200 if ok else 400)

    async def pump(app):
        """Push what is new to every page, at most `update_hz` times a second. A page gets a new LED frame only
        while fewer than `IN_FLIGHT` it was sent are not yet drawn (it says "drawn" for each), and only the newest:
        a slow browser sees fewer frames, never older ones (no queue builds up between the bus and the screen)."""
        seen: dict[Any, dict[str, int]] = {}
        sending: dict[Any, asyncio.Task] = {}
        loop = asyncio.get_running_loop()
        next_t = loop.time()
        while True:
            next_t += period
            await asyncio.sleep(max(0.0, next_t - loop.time()))
            if loop.time() - next_t > period:
                next_t = loop.time()
            for ws in list(clients):
                task = sending.get(ws)
                if task is not None and not task.done():
                    continue
                leds, updates = hub.since(seen.setdefault(ws, {}), leds=clients[ws] > 0)
                if leds is not None:
                    clients[ws] -= 1
                if leds is not None or updates:
                    sending[ws] = asyncio.create_task(_send(ws, leds, updates))
            for ws in list(seen):
                if ws not in clients:
                    seen.pop(ws, None)
                    sending.pop(ws, None)

    pump_task = web.AppKey("pump", asyncio.Task)

    async def start_pump(app):
        app[pump_task] = asyncio.create_task(pump(app))

    async def stop_pump(app):
        app[pump_task].cancel()
        for ws in list(clients):
            await ws.close()
        hub.close()

    app = web.Application(middlewares=[access])
    app.router.add_get("/", index)
    app.router.add_get("/geometry.json", geometry_json)
    app.router.add_get("/world.json", world_json)
    app.router.add_get("/ws", websocket)
    app.router.add_post("/cmd/{name}", command)
    app.on_startup.append(start_pump)
    app.on_shutdown.append(stop_pump)
    return app


async def _send(ws, leds: bytes | None, updates: dict[str, Any]) -> None:
    try:
        if updates:
            await ws.send_str(json.dumps({"type": "update", **updates}, allow_nan=False, default=str)
                              if _finite(updates) else json.dumps({"type": "update", **_nan_none(updates)}))
        if leds is not None:
            await ws.send_bytes(leds)
    except (ConnectionError, RuntimeError):
        pass


def _finite(obj: Any) -> bool:
    try:
        json.dumps(obj, allow_nan=False, default=str)
        return True
    except ValueError:
        return False


def _nan_none(obj: Any) -> Any:
    """NaN and infinities as null (JSON has neither)."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _nan_none(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_nan_none(v) for v in obj]
    return obj


def _call(session, rig: str, name: str, params: dict[str, Any], timeout_s: float = 10.0) -> tuple[bool, dict]:
    """A command over the bus, exactly as `antarium.Rig.call` sends it (the server validates it)."""
    replies = session.get(bus.command_key(rig, name), payload=json.dumps(params), timeout=timeout_s)
    for reply in replies:
        if reply.ok is not None:
            return True, json.loads(reply.ok.payload.to_bytes())
        try:
            return False, json.loads(reply.err.payload.to_bytes())
        except ValueError:
            return False, {"error": reply.err.payload.to_bytes().decode(errors="replace")}
    return False, {"error": f"{name}: no reply from rig {rig!r} within {timeout_s} s (server gone, or the command "
                            "was refused by the bus's access control)"}


def bind_error(exc: OSError) -> str:
    """Why the page's socket could not be bound, and which setting to change: the port when it is taken, else the
    address (a name that does not resolve, an address not this computer's)."""
    if exc.errno in (errno.EADDRINUSE, errno.EACCES):
        why = "in use (another monitor?)" if exc.errno == errno.EADDRINUSE else \
            f"refused: {exc.strerror} (ports below 1024 need privileges)"
        return f"{why}; set [monitor] port (or --port; 0: any free port)"
    return (f"refused: {exc.strerror or exc}; set [monitor] host (or --host) to an address of this computer "
            "(\"127.0.0.1\", \"0.0.0.0\" for the lab network)")


def page_url(host: str, port: int) -> str:
    """The page's address for a bound socket's `host` and `port`: an IPv6 address in brackets (RFC 3986)."""
    return f"http://[{host}]:{port}/" if ":" in host else f"http://{host}:{port}/"


def serve(session, rig: str, settings: MonitorSection, echo=print) -> None:
    """Run the web server until interrupted; prints its address once it listens."""
    from aiohttp import web

    async def main() -> None:
        runner = web.AppRunner(make_app(session, rig, settings), handle_signals=False)
        await runner.setup()
        site = web.TCPSite(runner, settings.host, settings.port)
        try:
            await site.start()
        except OSError as exc:
            await runner.cleanup()
            raise RuntimeError(f"the page cannot be served on {settings.host} port {settings.port}: "
                               f"{bind_error(exc)}") from None
        host, port = site._server.sockets[0].getsockname()[:2]
        echo(f"antarium monitor: rig {rig!r} at {page_url(host, port)} "
             f"(commands {'on' if settings.commands else 'off'})")
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        import signal

        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, stop.set)
        await stop.wait()
        await runner.cleanup()

    asyncio.run(main())
