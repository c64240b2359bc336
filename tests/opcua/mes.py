"""What the OPC UA test clients share: a client certificate, and a session signed in on the
encrypted endpoint (Basic256Sha256, SignAndEncrypt) with asyncua."""

import socket
from pathlib import Path

from asyncua import Client
from asyncua.crypto import cert_gen
from cryptography.x509.oid import ExtendedKeyUsageOID


async def certificate(work, name, app_uri):
    """A self-signed client certificate for `app_uri` in `work`: (key, cert) paths."""
    key, cert = Path(work) / f"{name}-key.pem", Path(work) / f"{name}-cert.der"
    await cert_gen.setup_self_signed_certificate(
        key,
        cert,
        app_uri,
        socket.gethostname(),
        [ExtendedKeyUsageOID.CLIENT_AUTH],
        {"commonName": f"edmd-test-{name}"},
    )
    return key, cert


async def signed_in(url, app_uri, key, cert, user, password):
    """A client (not connected yet) that signs in as `user` on the encrypted endpoint."""
    client = Client(url=url, timeout=10)
    client.application_uri = app_uri
    client.set_user(user)
    client.set_password(password)
    await client.set_security_string(f"Basic256Sha256,SignAndEncrypt,{cert},{key}")
    return client
