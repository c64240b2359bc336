#!/usr/bin/env python3
"""A Sparkplug B host for edmd's tests, decoding with PyPI's pysparkplug (not edmd's code).

    sparkplug.py listen --port P
        Subscribes to spBv1.0/# and prints one JSON line per message, decoded:
        {"type": "NBIRTH", "group": ..., "node": ..., "seq": ..., "metrics": {name: value},
         "at": unix time}. NDATA metrics come by alias and are named from the node's NBIRTH,
        as a Sparkplug host names them. Data from a node whose birth the host has not seen
        prints {"type": "unborn", ...}, and the host asks that node for its birth (NCMD
        Rebirth), as the specification asks of a host. A payload that does not decode prints
        {"type": "error", ...}.
    sparkplug.py ncmd --port P [--retain] [--name-bytes N] GROUP NODE METRIC
        Publishes an NCMD writing METRIC = true (e.g. "Node Control/Hold") and exits; with
        --retain, retained by the broker; with --name-bytes, the metric's name is METRIC
        padded with "x" to N bytes (an outsized command).
"""

import argparse
import json
import sys
import threading
import time

import pysparkplug as spb


DATA = (spb.MessageType.NDATA, spb.MessageType.DDATA)


class Unborn:
    """Data from a node whose birth this host has not seen (it subscribed after the birth)."""

    def __init__(self, topic) -> None:
        self.topic = topic

    def seen(self) -> dict:
        return {
            "type": "unborn",
            "data": str(self.topic.message_type),
            "group": self.topic.group_id,
            "node": self.topic.edge_node_id,
            "at": time.time(),
        }


def rebirth(client, group: str, node: str) -> None:
    """NCMD `Node Control/Rebirth = true` to `group/node`: a host that hears data from a
    node it has not seen born asks for the birth."""
    client.publish(ncmd_message(group, node, "Node Control/Rebirth"), include_dtypes=True)


def listen(port: int) -> None:
    client = spb.Client(client_id=f"edmd-test-host-{time.time_ns()}")
    connected = threading.Event()

    def on_message(_client, message) -> None:
        topic = message.topic
        payload = message.payload
        out = {
            "type": str(topic.message_type),
            "group": topic.group_id,
            "node": topic.edge_node_id,
            "at": time.time(),
        }
        if hasattr(payload, "seq"):
            out["seq"] = payload.seq
        if isinstance(payload, spb.NDeath):
            out["metrics"] = {"bdSeq": payload.bd_seq_metric.value}
        else:
            out["metrics"] = {m.name: m.value for m in payload.metrics}
        print(json.dumps(out, default=str), flush=True)

    def safe(client, message) -> None:
        if isinstance(message, Unborn):
            # As the specification asks of a host: data from a node whose birth it has not
            # seen is not decoded (its aliases mean nothing yet); the node is asked for it.
            print(json.dumps(message.seen()), flush=True)
            rebirth(client, message.topic.group_id, message.topic.edge_node_id)
            return
        try:
            if isinstance(message, Exception):
                raise message
            on_message(client, message)
        except Exception as e:  # a payload pysparkplug cannot decode is a test failure
            print(json.dumps({"type": "error", "why": repr(e)}), flush=True)

    # pysparkplug decodes in paho's network thread before our callback runs, and an
    # exception there ends that thread: the host would go deaf without a word. Decoding is
    # wrapped so that every message reaches `safe`, as a message, an Unborn or the error.
    decode = client._handle_message

    def decode_or_say_why(mqtt_message):
        topic = spb.Topic.from_str(mqtt_message.topic)
        key = (topic.group_id, topic.edge_node_id, topic.device_id)
        if topic.message_type in DATA and key not in client._births:
            return Unborn(topic)
        try:
            return decode(mqtt_message)
        except Exception as e:
            return e

    client._handle_message = decode_or_say_why

    # When the broker goes away and comes back, paho reconnects on its own; a refused
    # attempt on the way (the broker still starting) must not end the host, as pysparkplug's
    # connect callback would by raising in paho's thread.
    on_connect = client._on_connect

    def tolerant(rc) -> None:
        try:
            on_connect(rc)
        except Exception as e:
            print(json.dumps({"type": "connect-refused", "why": repr(e)}), flush=True)

    client._on_connect = tolerant
    client.subscribe(
        spb.Topic(group_id=spb.MULTI_LEVEL_WILDCARD), spb.QoS.AT_LEAST_ONCE, safe
    )
    client.connect("127.0.0.1", port=port, callback=lambda _c: connected.set())
    if not connected.wait(10):
        sys.exit("sparkplug.py: cannot connect to the broker")
    print(json.dumps({"type": "ready"}), flush=True)
    while True:
        time.sleep(3600)


def ncmd_message(group: str, node: str, metric: str, retain: bool = False):
    """An NCMD writing `metric` = true."""
    return spb.Message(
        topic=spb.Topic(
            message_type=spb.MessageType.NCMD, group_id=group, edge_node_id=node
        ),
        payload=spb.NCmd(
            timestamp=spb.get_current_timestamp(),
            metrics=(
                spb.Metric(
                    timestamp=spb.get_current_timestamp(),
                    name=metric,
                    datatype=spb.DataType.BOOLEAN,
                    value=True,
                ),
            ),
        ),
        qos=spb.QoS.AT_LEAST_ONCE,
        retain=retain,
    )


def ncmd(port: int, group: str, node: str, metric: str, retain: bool, name_bytes: int) -> None:
    client = spb.Client(client_id=f"edmd-test-cmd-{time.time_ns()}")
    connected = threading.Event()
    client.connect("127.0.0.1", port=port, callback=lambda _c: connected.set())
    if not connected.wait(10):
        sys.exit("sparkplug.py: cannot connect to the broker")
    if name_bytes > len(metric):
        metric = metric + "x" * (name_bytes - len(metric))
    client.publish(ncmd_message(group, node, metric, retain), include_dtypes=True)
    time.sleep(0.5)
    client.disconnect()


def main() -> None:
    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers(dest="what", required=True)
    p = sub.add_parser("listen")
    p.add_argument("--port", type=int, required=True)
    p = sub.add_parser("ncmd")
    p.add_argument("--port", type=int, required=True)
    p.add_argument("--retain", action="store_true")
    p.add_argument("--name-bytes", type=int, default=0)
    p.add_argument("group")
    p.add_argument("node")
    p.add_argument("metric")
    args = parser.parse_args()
    if args.what == "listen":
        listen(args.port)
    else:
        ncmd(args.port, args.group, args.node, args.metric, args.retain, args.name_bytes)


if __name__ == "__main__":
    main()
