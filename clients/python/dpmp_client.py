"""A small client for the dPMP trajectory service (standard library only).

    from dpmp_client import Client, DpmpError, points_obstacle

    dpmp = Client("http://127.0.0.1:8080")            # token=... when the service has one
    answer = dpmp.optimize(request)                    # the /v1/optimize request as a dict
    plan = dpmp.plan("plant.png", [392.1, 80.0, 424.4, 122.8],
                     depth_path="plant_depth.png", mask_applied=True,
                     obstacles=[...], clearance_m=0.02)
    print(plan["status"], plan["target"]["goal"], len(plan["trajectory"]["points"]))
    # The world the depth image sees, plus a cloud of your own:
    cloud = points_obstacle("shelf", [[0.9, 0.3, 0.2], [0.9, 0.32, 0.2]], 0.01)
    plan = dpmp.plan("plant.png", [392.1, 80.0, 424.4, 122.8], depth_path="plant_depth.png", world="depth",
                     obstacles=[cloud], clearance_m=0.015)
    print(plan["world"]["points"], plan["world"]["note"])

Every answer is the service's JSON as a dict (see api/openapi.yaml). A
refused request raises DpmpError with the server's `code`, `message` and
`field` (the offending input) and the HTTP status. A service that cannot be
reached (refused connection, unknown host, timeout) raises DpmpError too,
with `status` None, `code` "unreachable", a message naming the URL, and the
original exception as `__cause__`.
"""

import base64
import json
import socket
import struct
import urllib.error
import urllib.request

__all__ = ["Client", "DpmpError", "optimize", "plan", "points_obstacle"]

DEFAULT_URL = "http://127.0.0.1:8080"


class DpmpError(Exception):
    """A request the service refused: HTTP `status`, and its `code`,
    `message` and `field` (None when the error names no field). When the
    service could not be reached at all, `status` is None and `code` is
    "unreachable"."""

    def __init__(self, status, code, message, field=None):
        text = message if status is None else f"{status} {code}: {message}"
        super().__init__(text + (f" (field {field})" if field else ""))
        self.status = status
        self.code = code
        self.message = message
        self.field = field


class Client:
    """The service at `base_url`; `token` is the bearer token, if any;
    `timeout` in seconds per request."""

    def __init__(self, base_url=DEFAULT_URL, token=None, timeout=60.0):
        self.base_url = base_url.rstrip("/")
        self.token = token
        self.timeout = timeout

    def optimize(self, request):
        """POST /v1/optimize: the Mahalanobis-closest feasible trajectory for
        `request` (prior, obstacles, start, goal, ...)."""
        return self._post("/v1/optimize", request)

    def plan(self, image_path, box, depth_path=None, **fields):
        """POST /v1/plan: the network's prior for the berry in `box`
        ([x1, y1, x2, y2] px) of the image, then the optimised trajectory.
        With `depth_path` (aligned 16-bit PNG) the berry's 3-D position
        becomes the goal. Other request fields (mask_applied, obstacles,
        clearance_m, depth_scale_m, target_position, goal_standoff_m, ...)
        go in as keyword arguments."""
        body = dict(fields)
        body["image_base64"] = _file_base64(image_path)
        body["target_box"] = [float(v) for v in box]
        if depth_path is not None:
            body["depth_base64"] = _file_base64(depth_path)
        return self._post("/v1/plan", body)

    def robot(self):
        """GET /v1/robot: joints, limits, home, collision shapes."""
        return self._get("/v1/robot")

    def models(self):
        """GET /v1/models: the loaded network and its config."""
        return self._get("/v1/models")

    def ready(self):
        """Whether GET /readyz answers 200."""
        try:
            self._get("/readyz")
            return True
        except (DpmpError, OSError):
            return False

    def _get(self, path):
        return self._send(urllib.request.Request(self.base_url + path, method="GET"))

    def _post(self, path, body):
        data = json.dumps(body).encode("utf-8")
        request = urllib.request.Request(self.base_url + path, data=data, method="POST")
        request.add_header("Content-Type", "application/json")
        return self._send(request)

    def _send(self, request):
        if self.token:
            request.add_header("Authorization", f"Bearer {self.token}")
        try:
            with urllib.request.urlopen(request, timeout=self.timeout) as response:
                text = response.read().decode("utf-8")
                return json.loads(text) if text.strip().startswith(("{", "[")) else text
        except urllib.error.HTTPError as e:  # an answer: the service's error
            raise _error_of(e) from None
        except (urllib.error.URLError, ConnectionError, socket.timeout, TimeoutError) as e:
            raise self._unreachable(e) from e

    def _unreachable(self, error):
        """The DpmpError for a request that got no answer (`error`: the
        URLError, ConnectionError or timeout urllib raised)."""
        reason = error.reason if isinstance(error, urllib.error.URLError) else error
        hint = "is `dpmp serve` running?"
        if isinstance(reason, (socket.timeout, TimeoutError)):
            why = f"no answer within {self.timeout} s"
            hint = "is it overloaded, or the client's timeout too short?"
        elif isinstance(reason, ConnectionRefusedError):
            why = "connection refused"
        elif isinstance(reason, socket.gaierror):
            why = f"unknown host ({reason.strerror or reason})"
        else:
            why = getattr(reason, "strerror", None) or str(reason) or type(reason).__name__
        return DpmpError(
            None, "unreachable", f"cannot reach the dPMP service at {self.base_url}: {why}; {hint}"
        )


def _error_of(http_error):
    """The DpmpError of an HTTP error answer (`{"error": {...}}`)."""
    body = http_error.read().decode("utf-8", errors="replace")
    try:
        error = json.loads(body)["error"]
        return DpmpError(http_error.code, error.get("code"), error.get("message"), error.get("field"))
    except (ValueError, KeyError, TypeError):
        return DpmpError(http_error.code, "http_error", body.strip() or http_error.reason)


def _file_base64(path):
    with open(path, "rb") as f:
        return base64.b64encode(f.read()).decode("ascii")


def points_obstacle(obstacle_id, points, radius):
    """A `points` obstacle (a cloud: a ball of `radius` m around each of
    `points`, [[x, y, z], ...] in the base frame) in the compact form the
    service takes: `points_base64`, little-endian float32 triples."""
    packed = b"".join(struct.pack("<fff", *map(float, p)) for p in points)
    return {
        "id": obstacle_id,
        "type": "points",
        "points_base64": base64.b64encode(packed).decode("ascii"),
        "radius": float(radius),
    }


def optimize(request, base_url=DEFAULT_URL, token=None):
    """`Client(base_url, token).optimize(request)`."""
    return Client(base_url, token).optimize(request)


def plan(image_path, box, depth_path=None, base_url=DEFAULT_URL, token=None, **fields):
    """`Client(base_url, token).plan(image_path, box, depth_path, **fields)`."""
    return Client(base_url, token).plan(image_path, box, depth_path, **fields)
