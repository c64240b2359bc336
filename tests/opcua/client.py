"""A shop-floor OPC UA client against a running `edmd serve`, for tests/it/opcua.rs.

Usage: client.py URL PKI_DIR USER PASSWORD EDMD SOCKET WORK_DIR

Connects as the MES would (Python's asyncua), browses the machine, reads it while a job
runs, subscribes to its state and events, asks for a hold through `edmd ctl` and waits for
the change, tries the methods anonymously and signed in, and prints what it saw as one JSON
object on stdout. It asserts nothing itself: tests/it/opcua.rs judges what it saw.
"""

import asyncio
import json
import shutil
import subprocess
import sys
import time
from pathlib import Path

from asyncua import Client, ua

import mes

URL, PKI, USER, PASSWORD, EDMD, SOCKET, WORK = sys.argv[1:8]
NS = "urn:edmd:machine-tool"
APP_URI = "urn:edmd-test:mes"
seen = {}


async def tree(node, depth, prefix=""):
    """Browse names below `node`, as paths."""
    paths = []
    if depth == 0:
        return paths
    for child in await node.get_children():
        name = (await child.read_browse_name()).Name
        path = f"{prefix}/{name}" if prefix else name
        paths.append(path)
        paths += await tree(child, depth - 1, path)
    return paths


class Changes:
    """Data changes and events, as they arrive."""

    def __init__(self):
        self.states = []
        self.events = []

    def datachange_notification(self, node, val, data):
        self.states.append(val)

    def event_notification(self, event):
        self.events.append(
            {
                "type": event.EventType.Identifier,
                "message": event.Message.Text,
                "severity": event.Severity,
            }
        )


async def wait_for(predicate, seconds):
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        if predicate():
            return True
        await asyncio.sleep(0.05)
    return predicate()


def ctl(*args):
    return subprocess.run(
        [EDMD, "ctl", "--socket", SOCKET, *args], capture_output=True, text=True
    )


async def call_status(obj, method):
    try:
        out = await obj.call_method(method)
        return {"ok": True, "output": out}
    except ua.UaStatusCodeError as e:
        return {"ok": False, "status": type(e).__name__}


async def anonymous():
    async with Client(url=URL, timeout=10) as client:
        ns = await client.get_namespace_index(NS)
        machine = await client.nodes.objects.get_child([f"{ns}:Machines", f"{ns}:edmd"])
        seen["tree"] = await tree(machine, 4)
        ident = await machine.get_child([f"{ns}:Identification", f"{ns}:SoftwareRevision"])
        seen["software_revision"] = await ident.read_value()
        state = await machine.get_child([f"{ns}:Monitoring", f"{ns}:MachineTool", f"{ns}:State"])
        x = await machine.get_child(
            [f"{ns}:Monitoring", f"{ns}:Axes", f"{ns}:X", f"{ns}:ActualPosition"]
        )
        gap = await machine.get_child([f"{ns}:Monitoring", f"{ns}:EDMGenerator", f"{ns}:GapState"])
        program = await machine.get_child(
            [f"{ns}:Production", f"{ns}:ActiveProgram", f"{ns}:Name"]
        )
        line = await machine.get_child([f"{ns}:Production", f"{ns}:ActiveProgram", f"{ns}:Line"])
        seen["state_running"] = await state.read_value()
        seen["program"] = await program.read_value()
        seen["gap"] = await gap.read_value()
        xs = []
        for _ in range(5):
            xs.append(await x.read_value())
            await asyncio.sleep(0.3)
        seen["x_while_running"] = xs
        seen["line"] = await line.read_value()
        generator = [f"{ns}:Monitoring", f"{ns}:EDMGenerator"]
        seen["condition"] = await (
            await machine.get_child(generator + [f"{ns}:Condition"])
        ).read_value()
        seen["on_time"] = await (
            await machine.get_child(generator + [f"{ns}:OnTime"])
        ).read_value()
        seen["servo_ref"] = await (
            await machine.get_child(generator + [f"{ns}:ServoReferenceVoltage"])
        ).read_value()
        seen["wire_offset"] = await (
            await machine.get_child(generator + [f"{ns}:WireOffset"])
        ).read_value()
        seen["pass"] = await (
            await machine.get_child([f"{ns}:Production", f"{ns}:ActiveProgram", f"{ns}:Pass"])
        ).read_value()

        changes = Changes()
        sub = await client.create_subscription(50, changes)
        await sub.subscribe_data_change(state)
        await sub.subscribe_events(machine)
        production = await machine.get_child(f"{ns}:Production")
        hold = await production.get_child(f"{ns}:Hold")
        seen["hold_user_executable_anonymous"] = (
            await hold.read_attribute(ua.AttributeIds.UserExecutable)
        ).Value.Value
        seen["hold_anonymous"] = await call_status(production, hold)
        await asyncio.sleep(0.3)
        seen["state_after_anonymous_hold"] = await state.read_value()

        held = ctl("hold")
        seen["ctl_hold_exit"] = held.returncode
        await wait_for(lambda: "held" in changes.states, 10)
        await wait_for(lambda: any("hold" in e["message"] for e in changes.events), 3)
        seen["states"] = changes.states
        seen["events"] = changes.events
        seen["x_held"] = [await x.read_value()]
        await asyncio.sleep(0.5)
        seen["x_held"].append(await x.read_value())
        await sub.delete()


async def client_certificate():
    return await mes.certificate(WORK, "mes", APP_URI)


async def signed_in(key, cert, user, password):
    return await mes.signed_in(URL, APP_URI, key, cert, user, password)


async def secured():
    key, cert = await client_certificate()
    # An unknown client certificate: refused, and kept in rejected/ for the administrator.
    try:
        async with await signed_in(key, cert, USER, PASSWORD):
            seen["unknown_certificate"] = "accepted"
    except Exception as e:
        seen["unknown_certificate"] = type(e).__name__
    rejected = sorted((Path(PKI) / "rejected").glob("*.der"))
    seen["rejected"] = len(rejected)
    trusted = Path(PKI) / "trusted"
    trusted.mkdir(exist_ok=True)
    for c in rejected:
        shutil.move(str(c), str(trusted / c.name))
    # Trusted now, with a wrong password: refused.
    try:
        async with await signed_in(key, cert, USER, PASSWORD + "x"):
            seen["wrong_password"] = "accepted"
    except Exception as e:
        seen["wrong_password"] = type(e).__name__
    async with await signed_in(key, cert, USER, PASSWORD) as client:
        ns = await client.get_namespace_index(NS)
        production = await client.nodes.objects.get_child(
            [f"{ns}:Machines", f"{ns}:edmd", f"{ns}:Production"]
        )
        hold = await production.get_child(f"{ns}:Hold")
        abort = await production.get_child(f"{ns}:Abort")
        seen["hold_user_executable_signed_in"] = (
            await hold.read_attribute(ua.AttributeIds.UserExecutable)
        ).Value.Value
        seen["abort_signed_in"] = await call_status(production, abort)
        state = await client.nodes.objects.get_child(
            [f"{ns}:Machines", f"{ns}:edmd", f"{ns}:Monitoring", f"{ns}:MachineTool", f"{ns}:State"]
        )
        end = time.monotonic() + 10
        while time.monotonic() < end and await state.read_value() != "idle":
            await asyncio.sleep(0.1)
        seen["state_after_abort"] = await state.read_value()
        outcome = await client.nodes.objects.get_child(
            [f"{ns}:Machines", f"{ns}:edmd", f"{ns}:Production", f"{ns}:LastJob", f"{ns}:Outcome"]
        )
        seen["last_outcome"] = await outcome.read_value()
        seen["hold_when_idle"] = await call_status(production, hold)


asyncio.run(anonymous())
asyncio.run(secured())
print(json.dumps(seen, default=str))
