#!/usr/bin/env python3
"""A Sparkplug B host for edmd's tests, decoding with PyPI's pysparkplug (not edmd's code).

    sparkplug.py listen --port P
        Subscribes to spBv1.0/# and prints one JSON line per message, decoded:
        {"type": "NBIRTH", "group": ..., "node": ..., "seq": ..., "metrics": {name: value},
         "at": unix time}. NDATA metrics come by alias and are named from the node's NBIRTH,
        as a Sparkplug host names them; a payload that does not decode prints
        {"type": "error", ...}.
    sparkplug.py ncmd --port P GROUP NODE METRIC
        Publishes an NCMD writing METRIC = true (e.g. "Node Control/Hold") and exits.
"""

import argparse
import json
import sys
import threading
import time

import pysparkplug as spb


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
        try:
            on_message(client, message)
        except Exception as e:  # a payload pysparkplug cannot decode is a test failure
            print(json.dumps({"type": "error", "why": repr(e)}), flush=True)

    client.subscribe(
        spb.Topic(group_id=spb.MULTI_LEVEL_WILDCARD), spb.QoS.AT_LEAST_ONCE, safe
    )
    client.connect("127.0.0.1", port=port, callback=lambda _c: connected.set())
    if not connected.wait(10):
        sys.exit("sparkplug.py: cannot connect to the broker")
    print(json.dumps({"type": "ready"}), flush=True)
    while True:
        time.sleep(3600)


def ncmd(port: int, group: str, node: str, metric: str) -> None:
    client = spb.Client(client_id=f"edmd-test-cmd-{time.time_ns()}")
    connected = threading.Event()
    client.connect("127.0.0.1", port=port, callback=lambda _c: connected.set())
    if not connected.wait(10):
        sys.exit("sparkplug.py: cannot connect to the broker")
    message = spb.Message(
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
        retain=False,
    )
    client.publish(message, include_dtypes=True)
    time.sleep(0.5)
    client.disconnect()


def main() -> None:
    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers(dest="what", required=True)
    p = sub.add_parser("listen")
    p.add_argument("--port", type=int, required=True)
    p = sub.add_parser("ncmd")
    p.add_argument("--port", type=int, required=True)
    p.add_argument("group")
    p.add_argument("node")
    p.add_argument("metric")
    args = parser.parse_args()
    if args.what == "listen":
        listen(args.port)
    else:
        ncmd(args.port, args.group, args.node, args.metric)


if __name__ == "__main__":
    main()
