#!/usr/bin/env python3
"""Abuse cases against a running `dpmp serve` on loopback (stdlib only).

Run by scripts/abuse.sh, which starts the server. Every case is bounded in
count and time and prints its figures:

  zombie   three 0.05 s-duration requests and three maximal requests at
           once: answer times, solver jobs still running after the answers,
           and an ordinary request right after
  slow     clients that send headers one byte at a time: when the server
           cuts them, /healthz latency meanwhile
  flood    thousands of idle connections against the cap: /healthz latency,
           open descriptors and resident memory of the server
  decode   64 concurrent small PNGs declaring 4096x4096 RGBA16 on /v1/plan:
           answers, client wait against the deadline, peak memory
  (the shutdown case is in abuse.sh: it signals the server)
"""

import base64
import json
import os
import socket
import struct
import sys
import threading
import time
import urllib.request
import zlib

ADDR = os.environ.get("ADDR", "127.0.0.1:18081")
HOST, PORT = ADDR.split(":")[0], int(ADDR.split(":")[1])
PID = int(os.environ["SERVER_PID"])
BODY_DIR = os.environ.get("OUT", "target/abuse")


def url(path):
    return f"http://{ADDR}{path}"


def post(path, body, timeout=30.0):
    """(status, parsed JSON, seconds)."""
    data = body if isinstance(body, bytes) else json.dumps(body).encode()
    req = urllib.request.Request(url(path), data=data, headers={"content-type": "application/json"})
    t0 = time.monotonic()
    try:
        with urllib.request.urlopen(req, timeout=timeout) as r:
            status, text = r.status, r.read()
    except urllib.error.HTTPError as e:
        status, text = e.code, e.read()
    return status, json.loads(text or b"{}"), time.monotonic() - t0


def healthz_ms():
    t0 = time.monotonic()
    try:
        with urllib.request.urlopen(url("/healthz"), timeout=10) as r:
            r.read()
        return (time.monotonic() - t0) * 1e3
    except Exception:
        return float("inf")


def metric(name):
    with urllib.request.urlopen(url("/metrics"), timeout=10) as r:
        for line in r.read().decode().splitlines():
            if line.startswith(name + " ") or line.startswith(name + "{"):
                return float(line.split()[-1])
    return float("nan")


def proc(field):
    for line in open(f"/proc/{PID}/status"):
        if line.startswith(field):
            return line.split(":")[1].strip()
    return "?"


def fds():
    return len(os.listdir(f"/proc/{PID}/fd"))


def concurrently(fn, args_list):
    out = [None] * len(args_list)

    def run(i, args):
        out[i] = fn(*args)

    threads = [threading.Thread(target=run, args=(i, a)) for i, a in enumerate(args_list)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(120)
    return out


def zombie():
    typical = json.load(open(f"{BODY_DIR}/typical.json"))
    short = dict(typical, duration_s=0.05)
    maximal = json.loads(json.dumps(typical))
    for k in range(len(maximal["obstacles"]), 256):
        f = k / 256
        maximal["obstacles"].append({"id": f"far-{k}", "type": "sphere",
                                     "center": [-0.6 + 0.2 * f, -0.5 + f, 0.3 + 0.5 * f], "radius": 0.02})
    maximal["promp"]["n_samples"] = 2000
    maximal["options"].update(verify_factor=5, restarts=32, max_iterations=1000)
    maximal["samples"] = 32
    for name, body in [("duration_s 0.05", short), ("maximal", maximal)]:
        t0 = time.monotonic()
        answers = concurrently(post, [("/v1/optimize", body)] * 3)
        last = max(a[2] for a in answers)
        running = None
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline:
            running = metric("dpmp_solver_jobs_running")
            if running == 0:
                break
            time.sleep(0.01)
        idle_after = time.monotonic() - t0 - last
        statuses = [(a[0], a[1].get("status") or a[1].get("error", {}).get("code")) for a in answers]
        print(f"zombie {name}: answers {statuses} in {[round(a[2], 3) for a in answers]} s; "
              f"jobs running after the last answer: {running:.0f} (idle {idle_after * 1e3:.0f} ms later)")
        if name == "duration_s 0.05":
            a = answers[0][1]
            print(f"  duration_lower_bound_s {a.get('duration_lower_bound_s')}, "
                  f"min_duration_s {a.get('min_duration_s')}, report.solve_ms {a['report']['solve_ms']:.0f}")
        s, a, dt = post("/v1/optimize", typical)
        print(f"  an ordinary request right after: {s} {a.get('status')} in {dt * 1e3:.0f} ms")


def slow():
    n = 50
    socks = []
    for _ in range(n):
        s = socket.create_connection((HOST, PORT))
        s.settimeout(30)
        socks.append(s)
    t0 = time.monotonic()
    closed_at = [None] * n
    lat = []

    def trickle(i, s):
        try:
            for ch in b"POST /v1/optimize HTTP/1.1\r\nhost: x\r\n":
                s.sendall(bytes([ch]))
                time.sleep(0.1)
                if time.monotonic() - t0 > 20:
                    break
        except OSError:
            pass
        try:
            s.recv(1)
        except OSError:
            pass
        closed_at[i] = time.monotonic() - t0

    threads = [threading.Thread(target=trickle, args=(i, s)) for i, s in enumerate(socks)]
    for t in threads:
        t.start()
    while any(t.is_alive() for t in threads) and time.monotonic() - t0 < 25:
        lat.append(healthz_ms())
        time.sleep(0.2)
    for t in threads:
        t.join(1)
    done = [c for c in closed_at if c is not None]
    print(f"slow headers: {n} clients at 1 byte/100 ms cut after {min(done):.1f}-{max(done):.1f} s "
          f"(header timeout); /healthz meanwhile max {max(lat):.1f} ms over {len(lat)} probes")


def flood():
    before = (fds(), proc("VmRSS"))
    socks = []
    t0 = time.monotonic()
    for _ in range(int(os.environ.get("FLOOD", "5000"))):
        try:
            s = socket.create_connection((HOST, PORT), timeout=2)
            socks.append(s)
        except OSError:
            break
    opened = time.monotonic() - t0
    lat = [healthz_ms() for _ in range(20)]
    during = (fds(), proc("VmRSS"))
    for s in socks:
        s.close()
    time.sleep(0.5)
    after = (fds(), proc("VmRSS"))
    lat.sort()
    print(f"flood: {len(socks)} idle connections opened in {opened:.1f} s; /healthz p50 {lat[10]:.1f} ms, "
          f"max {lat[-1]:.1f} ms; server fds / RSS before {before}, during {during}, after {after}")


def png_bomb(width=4096, height=4096):
    """A PNG declaring width x height RGBA16, every pixel zero (compresses
    ~1000:1)."""
    row = b"\x00" + b"\x00" * (width * 8)
    raw = zlib.compress(row * height, 9)

    def chunk(kind, data):
        body = kind + data
        return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body) & 0xFFFFFFFF)

    ihdr = struct.pack(">IIBBBBB", width, height, 16, 6, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", raw) + chunk(b"IEND", b"")


def decode():
    bomb = png_bomb()
    body = json.dumps({"image_base64": base64.b64encode(bomb).decode(), "target_box": [10, 10, 60, 60],
                       "mask_applied": True, "target_position": [0.66, 0.0, 0.7]}).encode()
    hwm_before = proc("VmHWM")
    lat = []
    stop = threading.Event()

    def probe():
        while not stop.is_set():
            lat.append(healthz_ms())
            time.sleep(0.1)

    prober = threading.Thread(target=probe)
    prober.start()
    t0 = time.monotonic()
    answers = concurrently(post, [("/v1/plan", body, 60.0)] * 64)
    took = time.monotonic() - t0
    stop.set()
    prober.join()
    codes = {}
    for s, a, _ in answers:
        key = f"{s} {a.get('status') or a.get('error', {}).get('code')}"
        codes[key] = codes.get(key, 0) + 1
    waits = sorted(a[2] for a in answers)
    print(f"decode burst: 64 x {len(bomb) // 1024} KB PNGs declaring 4096x4096 RGBA16 -> {codes}; "
          f"client wait p50 {waits[32]:.2f} s, max {waits[-1]:.2f} s (deadline 2 s) in {took:.1f} s; "
          f"/healthz max {max(lat):.0f} ms; peak RSS {hwm_before} -> {proc('VmHWM')}")


if __name__ == "__main__":
    for case in sys.argv[1:] or ["zombie", "slow", "flood", "decode"]:
        globals()[case]()
