"""A ROS 2 end for the auvnav-bridge test, with no ROS install: a Zenoh session (the eclipse-zenoh
package) subscribes with rmw_zenoh's key expressions, reads the liveliness graph, and decodes
every payload with a third-party ROS 2 CDR decoder (rosbags), whose own RIHS01 type hashes are
compared with the ones in the key expressions. Prints one JSON document.

Usage: python3 ros2_listener.py ENDPOINT SECONDS
"""
import json
import math
import sys
import time

import zenoh
from rosbags.typesys import Stores, get_typestore


def leb128_string(b, i):
    n, shift = 0, 0
    while True:
        byte = b[i]
        i += 1
        n |= (byte & 0x7F) << shift
        shift += 7
        if byte < 0x80:
            break
    return b[i:i + n].decode(), i + n


def attachment(b):
    """rmw_zenoh's attachment: key strings and values in Zenoh's serialization."""
    out, i = {}, 0
    for key, size in (("sequence_number", 8), ("source_timestamp", 8), ("source_gid", 16)):
        name, i = leb128_string(b, i)
        if name != key:
            return {"error": f"expected {key}, found {name}"}
        raw = b[i:i + size]
        i += size
        out[key] = int.from_bytes(raw, "little", signed=True) if size == 8 else raw.hex()
    out["trailing"] = len(b) - i
    return out


def plain(x):
    """A decoded message as JSON-able data."""
    if hasattr(x, "__dataclass_fields__"):
        return {k: plain(getattr(x, k)) for k in x.__dataclass_fields__ if k != "__msgtype__"}
    if hasattr(x, "tolist"):
        return plain(x.tolist())
    if isinstance(x, (list, tuple)):
        return [plain(v) for v in x]
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def main():
    endpoint, seconds = sys.argv[1], float(sys.argv[2])
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    store = get_typestore(Stores.ROS2_JAZZY)
    got = {"topics": {}, "tokens": [], "errors": []}
    session = zenoh.open(conf)
    samples = []
    sub = session.declare_subscriber("0/**", lambda s: samples.append(
        (str(s.key_expr), bytes(s.payload.to_bytes()),
         bytes(s.attachment.to_bytes()) if s.attachment is not None else None)))
    print("ready", flush=True)
    time.sleep(seconds)
    for reply in session.liveliness().get("@ros2_lv/0/**", timeout=2.0):
        if reply.ok is not None:
            got["tokens"].append(str(reply.ok.key_expr))
    sub.undeclare()
    session.close()
    for key, payload, att in samples:
        parts = key.split("/")
        # <domain>/<topic...>/<dds type>/<hash>
        dds_type, type_hash = parts[-2], parts[-1]
        topic = "/" + "/".join(parts[1:-2])
        pkg, _msg, _dds, name = dds_type.split("::")
        ros_type = f"{pkg}/msg/{name.rstrip('_')}"
        t = got["topics"].setdefault(topic, {
            "type": ros_type, "key_hash": type_hash, "rosbags_hash": store.hash_rihs01(ros_type),
            "count": 0, "first": None, "last": None, "attachments": [], "diagnostics": []})
        try:
            msg = plain(store.deserialize_cdr(payload, ros_type))
        except Exception as e:  # a payload the third-party decoder refuses is a failure
            got["errors"].append(f"{topic}: {e}")
            continue
        t["count"] += 1
        t["first"] = t["first"] or msg
        t["last"] = msg
        if ros_type == "diagnostic_msgs/msg/DiagnosticArray":
            t["diagnostics"].extend(msg["status"])
        if len(t["attachments"]) < 3 and att is not None:
            t["attachments"].append(attachment(att))
    print(json.dumps(got), flush=True)


if __name__ == "__main__":
    main()
