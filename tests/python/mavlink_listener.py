"""A MAVLink ground end for the auvnav-mavlink test: listens with pymavlink on a UDP port, decodes
every message for a while, and prints what arrived as one JSON document.

Usage: python3 mavlink_listener.py PORT SECONDS
"""
import json
import math
import sys
import time

from pymavlink import mavutil


def finite(x):
    return x if isinstance(x, (int,)) or (isinstance(x, float) and math.isfinite(x)) else None


def main():
    port, seconds = int(sys.argv[1]), float(sys.argv[2])
    m = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", dialect="ardupilotmega")
    print("ready", flush=True)
    end = time.monotonic() + seconds
    got = {"counts": {}, "odometry": [], "gps_input": [], "origins": [], "status": [],
           "heartbeats": [], "bad": 0, "sources": []}
    while time.monotonic() < end:
        msg = m.recv_match(blocking=True, timeout=0.2)
        if msg is None:
            continue
        t = msg.get_type()
        if t == "BAD_DATA":
            got["bad"] += 1
            continue
        got["counts"][t] = got["counts"].get(t, 0) + 1
        src = [msg.get_srcSystem(), msg.get_srcComponent()]
        if src not in got["sources"]:
            got["sources"].append(src)
        now = time.monotonic()
        if t == "ODOMETRY":
            got["odometry"].append({
                "rx": now, "time_usec": msg.time_usec, "x": msg.x, "y": msg.y, "z": msg.z,
                "q": list(msg.q), "vx": msg.vx, "vy": msg.vy, "vz": msg.vz,
                "pose_covariance": [finite(v) for v in msg.pose_covariance],
                "velocity_covariance": [finite(v) for v in msg.velocity_covariance],
                "frame_id": msg.frame_id, "child_frame_id": msg.child_frame_id,
                "reset_counter": msg.reset_counter, "estimator_type": msg.estimator_type,
                "quality": msg.quality})
        elif t == "GPS_INPUT":
            got["gps_input"].append({
                "rx": now, "lat": msg.lat, "lon": msg.lon, "alt": msg.alt, "fix_type": msg.fix_type,
                "horiz_accuracy": msg.horiz_accuracy, "vn": msg.vn, "ve": msg.ve,
                "time_week": msg.time_week, "time_week_ms": msg.time_week_ms})
        elif t == "SET_GPS_GLOBAL_ORIGIN":
            got["origins"].append({"latitude": msg.latitude, "longitude": msg.longitude,
                                   "altitude": msg.altitude, "target_system": msg.target_system})
        elif t == "STATUSTEXT":
            got["status"].append({"severity": msg.severity, "text": msg.text})
        elif t == "HEARTBEAT":
            got["heartbeats"].append({"rx": now, "type": msg.type, "autopilot": msg.autopilot,
                                      "system_status": msg.system_status})
    print(json.dumps(got), flush=True)


if __name__ == "__main__":
    main()
