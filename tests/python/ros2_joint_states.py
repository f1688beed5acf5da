#!/usr/bin/env python3
"""What a ROS 2 node on rmw_zenoh (Jazzy) would receive of a cell's joint states, checked
without ROS: eclipse-zenoh takes the samples off the line, PyPI rosbags (0.11.9) decodes the
CDR payload as sensor_msgs/msg/JointState, encodes the message again (the bytes must be the
same) and computes the type hash the key must carry.

    ros2_joint_states.py --connect tcp/HOST:PORT --domain D --namespace NS [--samples N] [--pose]

Prints one JSON object: the key, the frame, the names, the positions, the stamps (s), the
attachments' sequence numbers and GID (its publisher's, as rmw_zenoh makes it: XXH3-128 of
the publisher's graph token, PyPI xxhash); with --pose also one tool pose
(geometry_msgs/msg/PoseStamped on tool_pose, checked the same way); and "graph": the node
and publisher tokens in ROS 2's graph (liveliness `@ros2_lv/<domain>/...`), each checked
against the layout of rmw_zenoh's design document and the data keys. Exit 1 with the reason
on stderr if anything differs from what rmw_zenoh writes or nothing arrives within 30 s.
"""
import argparse
import json
import queue
import struct
import sys

import xxhash
import zenoh
from rosbags.typesys import Stores, get_typestore

TYPE = "sensor_msgs/msg/JointState"


def fail(why):
    print(why, file=sys.stderr)
    sys.exit(1)


def take(args, topic, n):
    """The first `n` samples (key, payload, attachment) of `topic` under the namespace, of any
    type and hash: the key must name them itself."""
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps("peer"))
    conf.insert_json5("connect/endpoints", json.dumps(args.connect))
    conf.insert_json5("scouting/multicast/enabled", "false")
    got = queue.Queue()
    key = f"{args.domain}/{args.namespace}/{topic}/*/*"
    with zenoh.open(conf) as session:
        sub = session.declare_subscriber(key, lambda s: got.put(
            (str(s.key_expr), s.payload.to_bytes(),
             s.attachment.to_bytes() if s.attachment is not None else None)))
        samples = []
        # Room for the host's stalls: the cell publishes every status period (0.5 s).
        try:
            while len(samples) < n:
                samples.append(got.get(timeout=30))
        except queue.Empty:
            fail(f"{len(samples)} samples on {key}, then none in 30 s")
        sub.undeclare()
    return samples


def checked(store, sample, ros_type):
    """A sample of `ros_type` (`pkg/msg/Type`) as rmw_zenoh writes one: its key ends with
    the type and the hash rosbags computes, rosbags encodes the decoded message to the same
    bytes, its attachment is seq (i64), stamp (i64), 16, GID (16 bytes). Returns the message,
    the sequence number, the stamp (ns) and the GID (hex)."""
    key_expr, payload, attachment = sample
    pkg, _, name = ros_type.split("/")
    want = [f"{pkg}::msg::dds_::{name}_", store.hash_rihs01(ros_type)]
    if key_expr.split("/")[-2:] != want:
        fail(f"key {key_expr}: not .../{want[0]}/{want[1]}")
    msg = store.deserialize_cdr(payload, ros_type)
    again = bytes(store.serialize_cdr(msg, ros_type))
    if again != payload:
        fail(f"rosbags encodes the {name} as {again.hex()}, the cell sent {payload.hex()}")
    if attachment is None or len(attachment) != 33 or attachment[16] != 16:
        fail(f"attachment {attachment!r}: not seq (i64), stamp (i64), 16, GID (16 bytes)")
    seq, stamp_ns = struct.unpack("<qq", attachment[:16])
    return msg, seq, stamp_ns, attachment[17:].hex()


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--connect", action="append", required=True)
    ap.add_argument("--domain", type=int, required=True)
    ap.add_argument("--namespace", required=True)
    ap.add_argument("--samples", type=int, default=2)
    ap.add_argument("--pose", action="store_true", help="also one tool pose on tool_pose")
    args = ap.parse_args()

    store = get_typestore(Stores.ROS2_JAZZY)
    samples = take(args, "joint_states", args.samples)

    out = {"names": None, "positions": [], "stamps": [], "seqs": [], "gids": set()}
    for sample in samples:
        out["key"] = sample[0]
        msg, seq, stamp_ns, gid = checked(store, sample, TYPE)
        out["seqs"].append(seq)
        out["gids"].add(gid)
        out["frame"] = msg.header.frame_id
        out["names"] = list(msg.name)
        out["positions"].append([float(p) for p in msg.position])
        out["stamps"].append(msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9)
        out["attachment_stamps"] = out.get("attachment_stamps", []) + [stamp_ns * 1e-9]
        if len(msg.velocity) or len(msg.effort):
            out["velocity"], out["effort"] = list(msg.velocity), list(msg.effort)
    out["gids"] = sorted(out["gids"])
    if args.pose:
        out["pose"] = tool_pose(args, store)
    gids = {"joint_states": out["gids"], **({"tool_pose": [out["pose"]["gid"]]} if args.pose else {})}
    out["graph"] = graph(args, {"joint_states": out["key"],
                                **({"tool_pose": out["pose"]["key"]} if args.pose else {})}, gids)
    print(json.dumps(out))


def graph(args, data_keys, gids):
    """The cell's node and publishers in ROS 2's graph, as rmw_zenoh's design document lays
    its liveliness tokens out: `@ros2_lv/<domain>/<zid>/<nid>/<nid>/NN/<enclave>/<ns>/<node>`
    and `@ros2_lv/<domain>/<zid>/<nid>/<eid>/MP/<enclave>/<ns>/<node>/<topic>/<type>/<hash>/<qos>`,
    names mangled (`/` as `%`), each publisher's type and hash those of its data key."""
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps("peer"))
    conf.insert_json5("connect/endpoints", json.dumps(args.connect))
    conf.insert_json5("scouting/multicast/enabled", "false")
    ns = "%" + args.namespace
    with zenoh.open(conf) as session:
        tokens = sorted({str(r.ok.key_expr)
                         for r in session.liveliness().get(f"@ros2_lv/{args.domain}/**", timeout=20)
                         if r.ok is not None})
    nodes = [t.split("/") for t in tokens if t.split("/")[5:6] == ["NN"]]
    pubs = [t.split("/") for t in tokens if t.split("/")[5:6] == ["MP"]]
    if len(nodes) != 1:
        fail(f"graph: {len(nodes)} node tokens in {tokens}")
    node = nodes[0]
    if node[0] != "@ros2_lv" or node[1] != str(args.domain) or node[3] != node[4] \
            or node[6] != "%" or node[7] != ns or len(node) != 9:
        fail(f"graph: node token {'/'.join(node)}")
    zid, nid, name = node[2], node[3], node[8]
    found = {}
    for p in pubs:
        if len(p) != 13 or p[2] != zid or p[3] != nid or p[6] != "%" or p[7] != ns or p[8] != name:
            fail(f"graph: publisher token {'/'.join(p)} is not the node's")
        topic = p[9]
        leaf = topic.removeprefix(ns + "%")
        if leaf not in data_keys:
            fail(f"graph: publisher of {topic}, which the cell does not publish")
        want = data_keys[leaf].split("/")[-2:]
        if p[10:12] != want:
            fail(f"graph: {topic} declared as {p[10:12]}, published as {want}")
        token = "/".join(p)
        # rmw_zenoh's GID of a publisher: XXH3-128 of its token, low then high 64 bits, each
        # little-endian (`liveliness::Entity`); the same in each of its messages' attachments.
        gid = xxhash.xxh3_128_intdigest(token.encode()).to_bytes(16, "little").hex()
        if gids.get(leaf) != [gid]:
            fail(f"graph: {topic}'s messages carry GID {gids.get(leaf)}, its token hashes to {gid}")
        found[leaf] = {"token": token, "qos": p[12], "gid": gid}
    if sorted(found) != sorted(data_keys):
        fail(f"graph: publishers {sorted(found)}, topics {sorted(data_keys)}")
    # rmw_zenoh writes `zenoh::Id::to_string()`, Zenoh's own string of the 128-bit id: lower-case
    # hex without leading zeros (31 digits one time in 16).
    if not (1 <= len(zid) <= 32 and all(c in "0123456789abcdef" for c in zid)
            and not zid.startswith("0")):
        fail(f"graph: session id {zid!r} is not Zenoh's hex string of an id")
    return {"node": "/".join(node), "name": name, "publishers": found}


def tool_pose(args, store):
    """One tool pose (geometry_msgs/msg/PoseStamped), checked as the joint states are."""
    sample = take(args, "tool_pose", 1)[0]
    msg, _, _, gid = checked(store, sample, "geometry_msgs/msg/PoseStamped")
    p, o = msg.pose.position, msg.pose.orientation
    return {"frame": msg.header.frame_id, "position": [p.x, p.y, p.z],
            "orientation": [o.x, o.y, o.z, o.w], "gid": gid, "key": sample[0]}


if __name__ == "__main__":
    main()
