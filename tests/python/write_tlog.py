"""Writes a MAVLink telemetry log the way pymavlink's own loggers do (an 8-byte big-endian receive
time in microseconds, then the frame), for auvnav's tlog import test: a vehicle level, heading
30 degrees, 5 m deep, moving ahead at a steady 0.5 m/s, seen through ArduSub's streams (SCALED_IMU at 50 Hz,
SCALED_PRESSURE2 and ATTITUDE at 10 Hz, GPS_RAW_INT at 5 Hz) and a Water Linked DVL extension's
VISION_POSITION_DELTA at 5 Hz (component 197, as BlueOS's), with one frame's checksum damaged.
Prints what it wrote as JSON."""

import json
import math
import struct
import sys

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

out, seconds = sys.argv[1], float(sys.argv[2])
mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
dvl = mavlink2.MAVLink(None, srcSystem=1, srcComponent=197)
unix0_us = 1_733_436_754_000_000
boot0_ms = 90_000
counts = {"imu": 0, "pressure": 0, "attitude": 0, "gps": 0, "dvl": 0, "damaged": 0}
surface_hpa, density, g0 = 1013.25, 1025.0, 9.80665
depth = 5.0
speed, heading = 0.5, math.radians(30.0)
lat0, lon0 = 47.5, -122.3


def position(t_s):
    """Latitude and longitude (1e-7 deg) after t_s seconds on the straight track."""
    north, east = speed * t_s * math.cos(heading), speed * t_s * math.sin(heading)
    lat = lat0 + math.degrees(north / 6_371_000.0)
    lon = lon0 + math.degrees(east / (6_371_000.0 * math.cos(math.radians(lat0))))
    return round(lat * 1e7), round(lon * 1e7)


with open(out, "wb") as f:

    def record(t_us, msg, damage=False, sender=mav):
        buf = bytearray(msg.pack(sender))
        if damage:
            buf[-1] ^= 0x5A
        f.write(struct.pack(">Q", t_us) + bytes(buf))

    for k in range(int(seconds * 50)):
        boot_ms = boot0_ms + 20 * k
        received = unix0_us + 20_000 * k + 4_000 + (k * 7919 % 23) * 1000
        imu = mav.scaled_imu_encode(boot_ms, 0, 0, -1000, 0, 0, 0, 190, 40, 430)
        damaged = k == 777
        record(received, imu, damage=damaged)
        counts["damaged" if damaged else "imu"] += 1
        if k % 5 == 0:
            press = surface_hpa if k == 0 else surface_hpa + depth * density * g0 / 100.0
            record(received + 150, mav.scaled_pressure2_encode(boot_ms, press, 0.0, 1250))
            record(received + 250, mav.attitude_encode(boot_ms, 0.0, 0.0, 0.5236, 0, 0, 0))
            counts["pressure"] += 1
            counts["attitude"] += 1
        if k % 10 == 0:
            lat, lon = position(0.02 * k)
            record(
                received + 350,
                mav.gps_raw_int_encode(
                    unix0_us + 20_000 * k, 3, lat, lon, -5000, 110, 180, 0, 0, 12,
                ),
            )
            counts["gps"] += 1
            # Straight ahead: 0.1 m forward in the 0.2 s since the last ping, 90 % confidence.
            delta = dvl.vision_position_delta_encode(
                unix0_us + 20_000 * k, 200_000, [0.0, 0.0, 0.0], [speed * 0.2, 0.0, 0.0], 90.0
            )
            record(received + 450, delta, sender=dvl)
            counts["dvl"] += 1
print(json.dumps(counts))
