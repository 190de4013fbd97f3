#!/usr/bin/env python3
"""ArduSub SITL flying on auvnav: the closed loop and its checks.

SITL's physics moves the vehicle; `auvnav sitl-sensors` turns its true state into an IMU and a DVL
on pseudo-terminals; the drivers, the daemon and auvnav-mavlink run as processes; auvnav-mavlink
sends ODOMETRY to SITL (and takes SITL's pressure sensor as the depth, the autopilot as a source);
ArduSub's EKF3 navigates on it while this script flies the vehicle as a ground station would
(pymavlink on SITL's first port) and measures:

  external navigation  EKF3 says it uses external nav; EKF_STATUS_REPORT's flags and test ratios
  following            EKF3's position against auvnav's solution (RMS, lag) and both against truth
  dive + square        GUIDED: 5 m deep, a 10 m square, each corner reached
  position hold        POSHOLD for --hold-s: the radius SITL's true position wanders
  degraded             the DVL driver stopped for 20 s: auvnav degraded (quality 50), EKF3 on it
  lost stream          auvnav-mavlink stopped for 10 s: what EKF3 does, and its recovery
  new auvnav-mavlink   restarted away from its first origin: EKF3 must not jump
  daemon restart       auvnavd stopped 5 s and started from its checkpoint: EKF3 takes it back
  telemetry log        SITL's own tlog through `auvnav import tlog`, `info` and `replay`

Run through scripts/sitl/closed-loop.sh, which builds SITL and auvnav first. Prints a table, writes
OUT/figures.json, and exits non-zero when a check fails.
"""
import argparse
import csv
import json
import math
import os
import signal
import subprocess
import sys
import time

from pymavlink import mavutil

MODES = {"MANUAL": 19, "STABILIZE": 0, "ALT_HOLD": 2, "GUIDED": 4, "POSHOLD": 16, "AUTO": 3}
EKF_VEL_HORIZ, EKF_POS_HORIZ_ABS, EKF_CONST_POS = 0x02, 0x10, 0x80
EARTH_RADIUS = 6378137.0


def now_ns():
    return time.monotonic_ns()


class Loop:
    def __init__(self, a):
        self.a = a
        self.out = os.path.abspath(a.out)
        os.makedirs(self.out, exist_ok=True)
        self.procs = {}
        self.events = []  # (monotonic ns, kind, fields)
        self.texts = []
        self.prefix = f"sitl{os.getpid()}"

    # ---- processes -------------------------------------------------------------------------
    def spawn(self, name, argv, cwd=None, log_name=None):
        log = open(os.path.join(self.out, f"{log_name or name}.log"), "wb")
        env = dict(os.environ, RUST_LOG=os.environ.get("RUST_LOG", "info"))
        p = subprocess.Popen(argv, stdout=log, stderr=subprocess.STDOUT, cwd=cwd or self.out,
                             env=env, start_new_session=True)
        self.procs[name] = p
        return p

    def stop_all(self):
        # SITL first: `auvnav sitl-sensors` ends when its link closes, and says what it played.
        sitl = self.procs.get("sitl")
        if sitl is not None and sitl.poll() is None:
            os.killpg(sitl.pid, signal.SIGTERM)
            try:
                self.procs["sitl-sensors"].wait(timeout=10)
            except (KeyError, subprocess.TimeoutExpired):
                pass
        for name in reversed(list(self.procs)):
            p = self.procs[name]
            if p.poll() is None:
                try:
                    os.killpg(p.pid, signal.SIGCONT)
                    os.killpg(p.pid, signal.SIGTERM)
                except ProcessLookupError:
                    pass
        deadline = time.time() + 10
        for p in self.procs.values():
            try:
                p.wait(timeout=max(0.1, deadline - time.time()))
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)

    def alive(self, name):
        return self.procs[name].poll() is None

    # ---- MAVLink ---------------------------------------------------------------------------
    def connect(self):
        for _ in range(100):
            try:
                self.gcs = mavutil.mavlink_connection("tcp:127.0.0.1:5760", source_system=255,
                                                      source_component=190)
                break
            except OSError:
                time.sleep(0.2)
        else:
            raise SystemExit("SITL's port 5760 never opened: see sitl.log")
        self.gcs.setup_logfile(os.path.join(self.out, "sitl.tlog"), mode="wb")
        self.gcs.wait_heartbeat(timeout=60)
        for msg_id, hz in [(108, 20), (32, 20), (193, 5), (33, 10), (30, 10), (26, 50),
                           (29, 10), (137, 10), (49, 1)]:
            self.interval(msg_id, hz)

    def interval(self, msg_id, hz):
        self.gcs.mav.command_long_send(1, 1, mavutil.mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                                       msg_id, int(1e6 / hz), 0, 0, 0, 0, 0)

    def pump(self, seconds, until=None):
        """Reads SITL for up to `seconds`, recording what the checks need; returns early when
        `until()` is true."""
        end = time.time() + seconds
        while time.time() < end:
            m = self.gcs.recv_match(blocking=True, timeout=0.2)
            if m is None:
                if until and until():
                    return True
                continue
            t = now_ns()
            k = m.get_type()
            if k == "STATUSTEXT":
                self.texts.append((t, m.get_srcComponent(), m.text))
            elif k == "SIM_STATE":
                self.events.append((t, "truth", (m.lat_int * 1e-7, m.lon_int * 1e-7, m.alt)))
                self.attitude = (m.roll, m.pitch, m.yaw)
            elif k == "LOCAL_POSITION_NED":
                self.events.append((t, "ekf", (m.x, m.y, m.z)))
            elif k == "EKF_STATUS_REPORT":
                self.events.append((t, "ekf_status", (m.flags, m.velocity_variance,
                                                      m.pos_horiz_variance, m.pos_vert_variance,
                                                      m.compass_variance)))
            elif k == "GPS_GLOBAL_ORIGIN":
                self.origin = (m.latitude * 1e-7, m.longitude * 1e-7, m.altitude * 1e-3)
            elif k == "HEARTBEAT" and m.get_srcComponent() == 1:
                self.armed = bool(m.base_mode & mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
                self.mode = m.custom_mode
            if until and until():
                return True
        return bool(until and until())

    def said(self, fragment, since=0):
        return any(fragment in text and t >= since for t, _, text in self.texts)

    def latest(self, kind):
        for t, k, v in reversed(self.events):
            if k == kind:
                return t, v
        return None

    def set_mode(self, name):
        # Asked again each second, as a ground station's pilot would: a mode the vehicle cannot
        # take yet (GUIDED before EKF3 has a position) is refused with a status text.
        ok = False
        for _ in range(10):
            self.gcs.mav.set_mode_send(1, mavutil.mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                                       MODES[name])
            ok = self.pump(1, lambda: getattr(self, "mode", None) == MODES[name])
            if ok:
                break
        if not ok:
            raise RuntimeError(f"SITL did not take mode {name}: {self.recent_texts()}")

    def recent_texts(self, n=5):
        return "; ".join(text for _, _, text in self.texts[-n:])

    def target(self, n, e, d):
        mask = 0b0000111111111000  # position only
        self.gcs.mav.set_position_target_local_ned_send(
            0, 1, 1, mavutil.mavlink.MAV_FRAME_LOCAL_NED, mask, n, e, d, 0, 0, 0, 0, 0, 0, 0, 0)

    def reached(self, target, within):
        """True position within `within` of the target horizontally, and EKF3's depth within it
        of the target's: EKF3's vertical is ArduSub's own pressure-sensor loop, referenced to
        the surface at boot, not to the origin's altitude."""
        p, e = self.truth_ned(), self.latest("ekf")
        return (p is not None and e is not None
                and math.hypot(p[0] - target[0], p[1] - target[1]) < within
                and abs(e[1][2] - target[2]) < within)

    def truth_at(self, t):
        """SITL's true position in EKF3's frame at monotonic time t (the latest before it)."""
        best = None
        for ti, k, v in reversed(self.events):
            if k == "truth" and ti <= t:
                best = v
                break
        return ned(self.origin, *best) if best and hasattr(self, "origin") else None

    def truth_ned(self):
        """SITL's true position in EKF3's local frame (its origin), metres."""
        got = self.latest("truth")
        if got is None or not hasattr(self, "origin"):
            return None
        lat, lon, alt = got[1]
        return ned(self.origin, lat, lon, alt)


def ned(origin, lat, lon, alt):
    lat0, lon0, alt0 = origin
    n = math.radians(lat - lat0) * EARTH_RADIUS
    e = math.radians(lon - lon0) * EARTH_RADIUS * math.cos(math.radians(lat0))
    return (n, e, -(alt - alt0))


def write_configs(loop, first):
    a, out, prefix = loop.a, loop.out, loop.prefix
    lat, lon, alt, (roll, pitch, yaw) = first
    euler = [round(math.degrees(x), 6) for x in (roll, pitch, yaw)]
    dev = os.path.join(out, "dev")
    daemon = f"""name = "auvnavd"
prefix = "{prefix}"
health_period_s = 0.5
[navigation]
imu_dt_from_device_time = true
[initial]
latitude_deg = {lat!r}
longitude_deg = {lon!r}
height_m = {alt!r}
velocity_ned_m_s = [0.0, 0.0, 0.0]
euler_deg = {euler!r}
[output]
nav_csv = "{out}/nav.csv"
diagnostics_csv = "{out}/diagnostics.csv"
[checkpoint]
path = "{out}/auvnavd.checkpoint.json"
[deadlines]
imu_s = 0.1
dvl_s = 3.0
depth_s = 3.0
"""
    files = {"auvnavd.toml": daemon,
             "initial.toml": daemon[daemon.index("[initial]"):daemon.index("[output]")]}
    for cls, proto, extra in [("imu", "xsens", "[settings]\nxsens_rate_hz = 200\n"),
                              ("dvl", "wldvl", "")]:
        files[f"{cls}.toml"] = (
            f'prefix = "{prefix}"\nprotocol = "{proto}"\n[serial]\nport = "{dev}/{cls}"\n'
            f"baud = 921600\n{extra}[timing]\nreconnect_initial_s = 0.05\nreconnect_max_s = 0.5\n"
            "health_period_s = 0.5\n")
    # SITL's first pressure sensor: ArduSub's SITL water (1024 kg/m^3, 1013.25 hPa at altitude 0).
    files["mavlink.toml"] = f"""prefix = "{prefix}"
address = "tcpout:127.0.0.1:5763"
system_id = 1
component_id = 197
message = "{a.message}"
rate_hz = {a.rate_hz!r}
heartbeat_period_s = 1.0
[source]
imu = false
depth = true
pressure_instance = 1
depth_hz = 10.0
water_density_kg_m3 = 1024.0
surface_pressure_hpa = 1013.25
"""
    for name, text in files.items():
        with open(os.path.join(out, name), "w") as f:
            f.write(text)


def start_auvnav(loop, bins):
    out = loop.out
    b = lambda n: os.path.join(bins, n)
    loop.spawn("record", [b("auvnav"), "record", "--force", "--out", f"{out}/record.mcap",
                          "--prefix", loop.prefix])
    loop.spawn("auvnavd", [b("auvnavd"), "--config", f"{out}/auvnavd.toml"])
    loop.spawn("sitl-sensors", [b("auvnav"), "sitl-sensors", "--mavlink",
                                "tcpout:127.0.0.1:5762", "--link-dir", f"{out}/dev",
                                "--seed", str(loop.a.seed), "--json"])
    for _ in range(100):
        if os.path.exists(f"{out}/dev/imu") and os.path.exists(f"{out}/dev/dvl"):
            break
        time.sleep(0.1)
    loop.spawn("auvnav-imu", [b("auvnav-imu"), "--config", f"{out}/imu.toml"])
    loop.spawn("auvnav-dvl", [b("auvnav-dvl"), "--config", f"{out}/dvl.toml"])
    loop.spawn("auvnav-mavlink", [b("auvnav-mavlink"), "--config", f"{out}/mavlink.toml"])


def read_nav(path):
    rows = []
    with open(path) as f:
        for r in csv.DictReader(f):
            rows.append((int(r["time_ns"]), math.degrees(float(r["latitude_rad"])),
                         math.degrees(float(r["longitude_rad"])), float(r["height_m"]),
                         int(r["mode"])))
    return rows


def interpolate(series, t):
    """series: sorted [(t, (x, y, z))]; the value at t, or None outside."""
    lo, hi = 0, len(series) - 1
    if not series or t < series[0][0] or t > series[-1][0]:
        return None
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if series[mid][0] <= t:
            lo = mid
        else:
            hi = mid
    (t0, a), (t1, b) = series[lo], series[hi]
    w = 0.0 if t1 == t0 else (t - t0) / (t1 - t0)
    return tuple(x + w * (y - x) for x, y in zip(a, b))


def rms_horizontal(a, b, shift_ns=0):
    """RMS horizontal difference of series a against b shifted (b's value shift_ns later)."""
    s, n = 0.0, 0
    for t, p in a:
        q = interpolate(b, t + shift_ns)
        if q is not None:
            s += (p[0] - q[0]) ** 2 + (p[1] - q[1]) ** 2
            n += 1
    return (math.sqrt(s / n), n) if n else (float("nan"), 0)


def figures(loop, phases):
    o = loop.origin
    nav = [(t, ned(o, lat, lon, h)) for t, lat, lon, h, _ in read_nav(f"{loop.out}/nav.csv")]
    nav = nav[::10]  # 20 Hz is plenty against 20 Hz EKF3 positions
    ekf = [(t, v) for t, k, v in loop.events if k == "ekf"]
    truth = [(t, ned(o, *v)) for t, k, v in loop.events if k == "truth"]
    t0, t1 = phases["moving"]
    moving = lambda s: [(t, p) for t, p in s if t0 <= t <= t1]
    f = {}
    f["ekf_vs_auvnav_rms_m"], f["samples"] = rms_horizontal(moving(ekf), nav)
    lags = [(rms_horizontal(moving(ekf), nav, -lag * 10_000_000)[0], lag * 10)
            for lag in range(-50, 101)]
    f["ekf_vs_auvnav_best_rms_m"], f["ekf_lag_ms"] = min(lags)
    f["auvnav_vs_truth_rms_m"] = rms_horizontal(moving(nav), truth)[0]
    f["ekf_vs_truth_rms_m"] = rms_horizontal(moving(ekf), truth)[0]
    lost = phases.get("lost", (0, 0))
    status = [(t, v) for t, k, v in loop.events if k == "ekf_status" and t >= phases["ext_nav"]
              and not lost[0] <= t <= lost[1]]
    on = [v for _, v in status if v[0] & EKF_POS_HORIZ_ABS and v[0] & EKF_VEL_HORIZ
          and not v[0] & EKF_CONST_POS]
    f["ekf_status_reports"] = len(status)
    f["ekf_on_external_nav_fraction"] = len(on) / len(status) if status else 0.0
    f["ekf_max_velocity_test_ratio"] = max((v[1] for _, v in status), default=float("nan"))
    f["ekf_max_position_test_ratio"] = max((v[2] for _, v in status), default=float("nan"))
    return f


def tlog_check(loop):
    """SITL's own telemetry log (this run's ground-station link) through `auvnav import tlog`,
    `info` and `replay`: (ok, detail)."""
    out, auvnav = loop.out, os.path.join(loop.a.bin, "auvnav")
    imp = subprocess.run([auvnav, "import", "tlog", f"{out}/sitl.tlog", "--out", f"{out}/tlog.mcap",
                          "--pressure-instance", "1", "--surface-pressure-hpa", "1013.25",
                          "--water-density", "1024", "--json"], capture_output=True, text=True)
    if imp.returncode != 0:
        return False, f"import tlog failed: {imp.stderr.strip()[-300:]}"
    s = json.loads(imp.stdout)
    info = subprocess.run([auvnav, "info", f"{out}/tlog.mcap"], capture_output=True, text=True)
    replay = subprocess.run([auvnav, "replay", f"{out}/tlog.mcap", "--config",
                             f"{out}/initial.toml"], capture_output=True, text=True)
    ok = info.returncode == 0 and replay.returncode == 0 and s["imu"] > 0 and s["depth"] > 0
    return ok, (f"{s['frames']} frames: {s['imu']} IMU samples ({s['imu_source']}), "
                f"{s['depth']} depths, {s['attitude']} attitudes; info exit "
                f"{info.returncode}, replay exit {replay.returncode}")


def fly(loop):
    a = loop.a
    res = {"checks": {}}
    phases = {}
    check = lambda name, ok, detail: res["checks"].__setitem__(name, {"ok": bool(ok),
                                                                      "detail": detail})
    loop.pump(3)
    got = loop.latest("truth")
    if got is None:
        raise RuntimeError("no SIM_STATE from SITL")
    t_start = loop.t_auvnav
    # EKF3's words for the source it starts on: auvnav as external navigation, or as a GPS.
    taken = "is using external nav data" if loop.a.message == "odometry" else "is using GPS"
    ext = loop.pump(90, lambda: loop.said(taken) and hasattr(loop, "origin")
                    and (loop.latest("ekf_status") or (0, (0,)))[1][0] & EKF_POS_HORIZ_ABS)
    phases["ext_nav"] = now_ns()
    check("ekf_takes_external_nav", ext,
          f"{(now_ns() - t_start) / 1e9:.1f} s after auvnav started; origin "
          f"{getattr(loop, 'origin', None)}")
    if not ext:
        return res, phases
    loop.set_mode("MANUAL")
    loop.gcs.arducopter_arm()
    armed = loop.pump(15, lambda: getattr(loop, "armed", False))
    if not armed:
        reasons = loop.recent_texts()
        loop.gcs.mav.command_long_send(1, 1, mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1,
                                       21196, 0, 0, 0, 0, 0)
        armed = loop.pump(10, lambda: getattr(loop, "armed", False))
        check("arms_without_force", False, f"pre-arm: {reasons}")
    else:
        check("arms_without_force", True, "armed in MANUAL")
    loop.set_mode("GUIDED")
    phases["moving"] = [now_ns(), None]
    corners = [(0, 0, a.depth_m), (a.side_m, 0, a.depth_m), (a.side_m, a.side_m, a.depth_m),
               (0, a.side_m, a.depth_m), (0, 0, a.depth_m)]
    reached = []
    for c in corners:
        t_c = time.time()
        near = lambda: loop.reached(c, a.reach_m)
        ok = False
        while time.time() - t_c < a.leg_timeout_s and not ok:
            loop.target(*c)
            ok = loop.pump(1.0, near)
        reached.append((c, ok, round(time.time() - t_c, 1)))
        if not ok:
            break
    phases["moving"][1] = now_ns()
    check("guided_square", all(ok for _, ok, _ in reached) and len(reached) == len(corners),
          "; ".join(f"{c} {'reached' if ok else 'NOT reached'} in {s} s" for c, ok, s in reached))

    loop.set_mode("POSHOLD")
    p0 = loop.truth_ned()
    worst = 0.0
    t_h = time.time()
    while time.time() - t_h < a.hold_s:
        loop.pump(0.5)
        p = loop.truth_ned()
        worst = max(worst, math.hypot(p[0] - p0[0], p[1] - p0[1]))
    check("poshold", worst <= a.hold_radius_m,
          f"{a.hold_s:.0f} s: true position within {worst:.2f} m of where the hold began "
          f"(limit {a.hold_radius_m} m)")

    # A new auvnav-mavlink (a restart, an update): away from where the first one took its origin,
    # it must send positions in the frame EKF3 already has.
    far = (a.side_m, a.side_m, a.depth_m)
    loop.set_mode("GUIDED")
    t_c = time.time()
    while time.time() - t_c < a.leg_timeout_s and not loop.pump(
            1.0, lambda: loop.reached(far, a.reach_m)):
        loop.target(*far)
    loop.set_mode("POSHOLD")
    old = loop.procs["auvnav-mavlink"]
    os.killpg(old.pid, signal.SIGTERM)
    old.wait(timeout=10)
    loop.procs["auvnav-mavlink.1"] = old
    t_o = now_ns()
    loop.spawn("auvnav-mavlink", [os.path.join(a.bin, "auvnav-mavlink"), "--config",
                                  f"{loop.out}/mavlink.toml"], log_name="auvnav-mavlink.2")
    loop.pump(15)
    jump = max((math.hypot(v[0] - p[0], v[1] - p[1]) for t, k, v in loop.events
                if k == "ekf" and t >= t_o
                for p in [loop.truth_at(t)] if p is not None), default=float("nan"))
    drift = math.hypot(*(x - y for x, y in zip(loop.truth_ned()[:2], far[:2])))
    check("new_auvnav_mavlink", jump < 1.0 and drift < 2.0,
          f"auvnav-mavlink restarted {math.hypot(far[0], far[1]):.1f} m from the first one's "
          f"origin: EKF3 within {jump:.2f} m of the truth for the next 15 s, the vehicle "
          f"{drift:.2f} m from where it held")

    # Degraded: the DVL driver stops; auvnav reports it and goes on dead-reckoning (quality 50).
    t_d = now_ns()
    os.killpg(loop.procs["auvnav-dvl"].pid, signal.SIGSTOP)
    loop.pump(20)
    os.killpg(loop.procs["auvnav-dvl"].pid, signal.SIGCONT)
    loop.pump(10)
    res["auvnav_degraded_before_the_dvl_test"] = sum(
        1 for t, c, x in loop.texts if c == 197 and "auvnav: degraded" in x and t < t_d)
    deg = loop.said("auvnav: degraded", t_d)
    back = loop.said("auvnav: navigating", t_d)
    st = [v for t, k, v in loop.events if k == "ekf_status" and t >= t_d]
    kept = all(v[0] & EKF_POS_HORIZ_ABS for v in st)
    check("degraded", deg and back and kept,
          f"status texts seen by the ground station: degraded {deg}, navigating again {back}; "
          f"EKF3 kept its absolute position throughout: {kept} ({len(st)} reports)")

    # Lost stream: auvnav-mavlink stops; EKF3's external navigation times out.
    t_l = now_ns()
    os.killpg(loop.procs["auvnav-mavlink"].pid, signal.SIGSTOP)
    loop.pump(10)
    during = [v for t, k, v in loop.events if k == "ekf_status" and t >= t_l]
    lost_flags = sorted({hex(v[0]) for v in during})
    t_r = now_ns()
    os.killpg(loop.procs["auvnav-mavlink"].pid, signal.SIGCONT)
    recovered = loop.pump(30, lambda: (loop.latest("ekf_status") or (0, (0,)))[1][0]
                          & EKF_POS_HORIZ_ABS and loop.latest("ekf_status")[0] > t_r + 1e9)
    phases["lost"] = (t_l, now_ns())
    p_t, p_e = loop.truth_ned(), (loop.latest("ekf") or (0, (0, 0, 0)))[1]
    check("lost_stream", recovered,
          f"EKF3 flags during a 10 s silence: {', '.join(lost_flags)}; "
          f"{'recovered' if recovered else 'NOT recovered'} "
          f"{(now_ns() - t_r) / 1e9:.1f} s after the stream resumed; EKF3 to truth "
          f"{math.hypot(p_t[0] - p_e[0], p_t[1] - p_e[1]):.2f} m after")
    # auvnavd restarted mid-dive (an update, a crash): it continues from its checkpoint with the
    # covariance grown by the time it was away; EKF3 must take it back without a jump.
    old = loop.procs["auvnavd"]
    t_s = now_ns()
    os.killpg(old.pid, signal.SIGTERM)
    old.wait(timeout=10)
    loop.procs["auvnavd.1"] = old
    loop.pump(5)
    loop.spawn("auvnavd", [os.path.join(a.bin, "auvnavd"), "--config",
                           f"{loop.out}/auvnavd.toml"], log_name="auvnavd.2")
    t_b = now_ns()
    back = loop.pump(30, lambda: (loop.latest("ekf_status") or (0, (0,)))[0] > t_b + 2e9
                     and loop.latest("ekf_status")[1][0] & EKF_POS_HORIZ_ABS)
    loop.pump(20)
    p_t, p_e = loop.truth_ned(), (loop.latest("ekf") or (0, (0, 0, 0)))[1]
    err = math.hypot(p_t[0] - p_e[0], p_t[1] - p_e[1])
    texts = [x for t, c, x in loop.texts if c == 197 and t >= t_s]
    check("daemon_restart", back and err < 1.0,
          f"auvnavd stopped 5 s and started again from its checkpoint: EKF3 "
          f"{'back on' if back else 'NOT back on'} external navigation "
          f"{(now_ns() - t_b) / 1e9 - 20:.1f} s after; 20 s later {err:.2f} m from truth; "
          f"auvnav said: {'; '.join(texts) or 'nothing'}")
    loop.gcs.mav.command_long_send(1, 1, mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0,
                                   0, 0, 0, 0, 0, 0)
    loop.pump(2)
    return res, phases


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--ardusub", required=True, help="SITL's ardusub binary")
    p.add_argument("--sitl-defaults", required=True, help="ArduSub's sub.parm for SITL")
    p.add_argument("--parm", required=True, help="deploy/ardusub-auvnav.parm")
    p.add_argument("--bin", required=True, help="folder of auvnav's release binaries")
    p.add_argument("--out", default="target/sitl-closed-loop")
    p.add_argument("--home", default="47.397742,8.545594,0,0",
                   help="SITL's home: lat,lon,alt (0: the water surface),heading")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--rate-hz", type=float, default=10.0)
    p.add_argument("--message", choices=["odometry", "gps_input"], default="odometry",
                   help="what auvnav-mavlink sends: ODOMETRY (external navigation) or GPS_INPUT "
                        "(auvnav as a GPS: GPS1_TYPE 14, EKF3's position and velocity from GPS, "
                        "yaw from the compass)")
    p.add_argument("--depth-m", type=float, default=5.0)
    p.add_argument("--side-m", type=float, default=10.0)
    p.add_argument("--reach-m", type=float, default=1.0)
    p.add_argument("--leg-timeout-s", type=float, default=90.0)
    p.add_argument("--hold-s", type=float, default=60.0)
    p.add_argument("--hold-radius-m", type=float, default=1.0)
    p.add_argument("--json", action="store_true")
    a = p.parse_args()

    loop = Loop(a)
    sitl_dir = os.path.join(loop.out, "sitl")
    os.makedirs(sitl_dir, exist_ok=True)
    for stale in ("eeprom.bin", "mav.parm"):
        try:
            os.remove(os.path.join(sitl_dir, stale))
        except FileNotFoundError:
            pass
    res, phases = {}, {}
    a.bin = os.path.abspath(a.bin)
    defaults = [os.path.abspath(a.sitl_defaults), os.path.abspath(a.parm)]
    if a.message == "gps_input":
        overlay = os.path.join(loop.out, "gps-input.parm")
        with open(overlay, "w") as f:
            f.write("VISO_TYPE 0\nGPS1_TYPE 14\nEK3_SRC1_POSXY 3\nEK3_SRC1_VELXY 3\n"
                    "EK3_SRC1_VELZ 0\nEK3_SRC1_YAW 1\n")
        defaults.append(overlay)
    try:
        loop.spawn("sitl", [a.ardusub, "--model", "vectored", "--speedup", "1", "-I0",
                            "--home", a.home, "--defaults", ",".join(defaults)],
                   cwd=sitl_dir)
        loop.connect()
        if not loop.pump(30, lambda: loop.latest("truth") is not None):
            raise RuntimeError("no SIM_STATE from SITL in 30 s")
        t, (lat, lon, alt) = loop.latest("truth")
        write_configs(loop, (lat, lon, alt, loop.attitude))
        loop.t_auvnav = now_ns()
        start_auvnav(loop, a.bin)
        res, phases = fly(loop)
    except Exception as e:  # reported, then the processes are stopped
        res.setdefault("checks", {})["ran"] = {"ok": False, "detail": repr(e)}
    finally:
        loop.stop_all()
    if "moving" in phases and phases["moving"][1]:
        res["figures"] = figures(loop, phases)  # the daemon's CSV is complete once it stopped
    if os.path.exists(os.path.join(loop.out, "initial.toml")):
        ok, detail = tlog_check(loop)
        res.setdefault("checks", {})["telemetry_log"] = {"ok": ok, "detail": detail}
    res["processes"] = {n: p.returncode for n, p in loop.procs.items()}
    try:
        with open(os.path.join(loop.out, "sitl-sensors.log")) as f:
            last = [json.loads(x) for x in f if x.startswith("{")][-1]
        res["sitl_sensors"] = last.get("summary", last)
    except (OSError, ValueError, IndexError):
        pass
    res["auvnav_status_texts"] = [x for _, c, x in loop.texts if c == 197]
    res["autopilot_status_texts"] = [x for _, c, x in loop.texts if c != 197][-40:]
    with open(os.path.join(loop.out, "figures.json"), "w") as f:
        json.dump(res, f, indent=1)
    if a.json:
        print(json.dumps(res))
    else:
        for name, c in res.get("checks", {}).items():
            print(f"{'ok  ' if c['ok'] else 'FAIL'} {name}: {c['detail']}")
        for k, v in res.get("figures", {}).items():
            print(f"     {k}: {v:.3f}" if isinstance(v, float) else f"     {k}: {v}")
        print(f"     logs, tlog, record.mcap and figures.json in {loop.out}")
    sys.exit(0 if res.get("checks") and all(c["ok"] for c in res["checks"].values()) else 1)


if __name__ == "__main__":
    main()
