"""An MES dispatching jobs to a running `edmd serve` over OPC UA, for tests/it/opcua.rs.

Usage: jobs.py URL PKI_DIR USER PASSWORD WORK_DIR

Through JobManagement/JobOrderControl (after OPC 40001-3) with Python's asyncua: stores,
starts, pauses, resumes and aborts job orders, reads the job list's states as they change,
and each order's result from JobOrderResults. Prints what it saw as one JSON object; it
asserts nothing itself: tests/it/opcua.rs judges.
"""

import asyncio
import json
import shutil
import sys
import time
from pathlib import Path

from asyncua import Client, ua

import mes

URL, PKI, USER, PASSWORD, WORK = sys.argv[1:6]
NS = "urn:edmd:machine-tool"
APP_URI = "urn:edmd-test:mes-jobs"
seen = {}


def text(s):
    return ua.Variant(s, ua.VariantType.String)


def store_args(order, program, passes=0, technology="", work_system=""):
    return [
        text(order),
        text(program),
        ua.Variant(passes, ua.VariantType.UInt32),
        text(technology),
        text(work_system),
    ]


async def call(obj, name, *args):
    ns = obj.nodeid.NamespaceIndex
    try:
        out = await obj.call_method(f"{ns}:{name}", *args)
        return out if isinstance(out, list) else [out]
    except ua.UaStatusCodeError as e:
        return {"status": type(e).__name__}


async def certificate():
    return await mes.certificate(WORK, "mes-jobs", APP_URI)


async def signed_in(key, cert):
    return await mes.signed_in(URL, APP_URI, key, cert, USER, PASSWORD)


async def management(client):
    ns = await client.get_namespace_index(NS)
    base = [f"{ns}:Machines", f"{ns}:edmd", f"{ns}:JobManagement"]
    control = await client.nodes.objects.get_child(base + [f"{ns}:JobOrderControl"])
    results = await client.nodes.objects.get_child(base + [f"{ns}:JobOrderResults"])
    return ns, control, results


async def job_list(control, ns):
    ids = await (await control.get_child(f"{ns}:JobOrderIDs")).read_value()
    states = await (await control.get_child(f"{ns}:JobOrderStates")).read_value()
    return dict(zip(ids or [], states or []))


async def wait_state(control, ns, order, state, seconds=30):
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        if (await job_list(control, ns)).get(order) == state:
            return True
        await asyncio.sleep(0.1)
    return False


async def anonymous():
    async with Client(url=URL, timeout=10) as client:
        ns, control, _ = await management(client)
        seen["anonymous_store"] = await call(control, "Store", *store_args("X", "short.ngc"))


async def dispatch():
    key, cert = await certificate()
    try:  # an unknown certificate lands in rejected/; the administrator trusts it
        async with await signed_in(key, cert):
            pass
    except Exception:
        pass
    trusted = Path(PKI) / "trusted"
    trusted.mkdir(exist_ok=True)
    for c in sorted((Path(PKI) / "rejected").glob("*.der")):
        shutil.move(str(c), str(trusted / c.name))
    async with await signed_in(key, cert) as client:
        ns, control, results = await management(client)
        seen["store"] = await call(control, "Store", *store_args("J1", "short.ngc", 0, "", "G55"))
        seen["store_twice"] = await call(control, "Store", *store_args("J1", "short.ngc"))
        seen["store_missing"] = await call(control, "Store", *store_args("J9", "missing.ngc"))
        seen["store_escape"] = await call(control, "Store", *store_args("J9", "../x.ngc"))
        # The list follows within the server's refresh (0.1 s).
        await wait_state(control, ns, "J1", "AllowedToStart", 5)
        seen["list_stored"] = await job_list(control, ns)
        seen["start"] = await call(control, "Start", text("J1"))
        seen["running"] = await wait_state(control, ns, "J1", "Running")
        seen["pause"] = await call(control, "Pause", text("J1"))
        seen["interrupted"] = await wait_state(control, ns, "J1", "Interrupted")
        seen["start_while_running"] = await call(
            control, "StoreAndStart", *store_args("J2", "long.ngc")
        )
        seen["resume"] = await call(control, "Resume", text("J1"))
        seen["ended"] = await wait_state(control, ns, "J1", "Ended", 60)
        seen["result_j1"] = await call(
            results, "RequestJobResponseByJobOrderID", text("J1")
        )
        seen["start_j2"] = await call(control, "Start", text("J2"))
        seen["j2_running"] = await wait_state(control, ns, "J2", "Running")
        seen["abort_j2"] = await call(control, "Abort", text("J2"))
        seen["j2_aborted"] = await wait_state(control, ns, "J2", "Aborted")
        seen["result_j2"] = await call(
            results, "RequestJobResponseByJobOrderID", text("J2")
        )
        seen["store_j3"] = await call(control, "Store", *store_args("J3", "short.ngc"))
        seen["abort_j3"] = await call(control, "Abort", text("J3"))
        seen["clear_j3"] = await call(control, "Clear", text("J3"))
        seen["result_unknown"] = await call(
            results, "RequestJobResponseByJobOrderID", text("J3")
        )
        await asyncio.sleep(0.5)
        seen["list_end"] = await job_list(control, ns)


asyncio.run(anonymous())
asyncio.run(dispatch())
print(json.dumps(seen, default=str))
