"""Who may connect: the endpoint's rules off the loopback interface (:func:`check_endpoint`) and the server's
certificate (:func:`make_certificate`)."""

from __future__ import annotations

import hmac
import ipaddress
import os
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import urlparse

from ..errors import ConfigError

#: The server's ApplicationUri (OPC UA Part 4 7.2), also the URI its certificate carries (``--make-certificate``)
APPLICATION_URI = "urn:ncfmu:serve"


@dataclass
class Security:
    """Who may connect when the endpoint is not on the loopback interface."""

    users: dict[str, str] = field(default_factory=dict)     # name -> password
    certificate: Path | None = None                          # server certificate (DER or PEM)
    private_key: Path | None = None
    trust: Path | None = None                # folder of the client certificates (or their CAs) accepted
    allow_insecure: bool = False             # off the loopback: security policy None, any client certificate

    def admits(self, name: str | None, password: str | None) -> bool:
        """Whether ``name`` and ``password`` are one of ``users``, compared in constant time against every user
        (the answer's time tells neither whether the name exists nor how much of the password was right): the
        one check of the OPC UA server and the web page."""
        said_name = (name or "").encode()
        said_password = (password or "").encode()
        found = False
        for user, secret in self.users.items():
            found |= (hmac.compare_digest(user.encode(), said_name)
                      & hmac.compare_digest(secret.encode(), said_password))
        return found and name is not None and password is not None


def is_loopback_host(host: str) -> bool:
    """Whether ``host`` (a name or an address, IPv6 without brackets) is this machine's loopback: the one rule of
    the OPC UA endpoint and the web page's address."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def _is_loopback(endpoint: str) -> bool:
    return is_loopback_host(urlparse(endpoint).hostname or "")


def check_endpoint(endpoint: str, security: Security) -> None:
    parsed = urlparse(endpoint)
    try:
        port = parsed.port
    except ValueError:
        raise ConfigError("--endpoint", endpoint, "the port must be a number 0..65535") from None
    if parsed.scheme != "opc.tcp" or not parsed.hostname or port is None:
        raise ConfigError("--endpoint", endpoint, "must be opc.tcp://HOST:PORT/PATH")
    if not _is_loopback(endpoint):
        if not security.users:
            raise ConfigError("--endpoint", endpoint, "serving beyond this machine needs --user NAME:PASSWORD "
                              "(no anonymous writes from the network); bind 127.0.0.1 otherwise")
        if security.certificate is None and not security.allow_insecure:
            raise ConfigError("--endpoint", endpoint, "serving beyond this machine needs --certificate and "
                              "--private-key (security policy Basic256Sha256, Sign & Encrypt: no password or write "
                              "in plain text; 'ncfmu serve --make-certificate DIR' makes them), or --allow-insecure")
        if security.trust is None and not security.allow_insecure:
            raise ConfigError("--endpoint", endpoint, "serving beyond this machine needs --trust DIR (the client "
                              "certificates accepted), or --allow-insecure")
    if (security.certificate is None) != (security.private_key is None):
        raise ConfigError("--certificate", str(security.certificate), "needs --private-key too (and vice versa)")
    if security.trust is not None:
        if security.certificate is None:
            raise ConfigError("--trust", str(security.trust), "needs --certificate: client certificates are only "
                              "presented on a signed and encrypted channel")
        if not Path(security.trust).is_dir():
            raise ConfigError("--trust", str(security.trust), "must be a folder of trusted certificates (DER or PEM)")


def make_certificate(folder: Path | str, hostname: str | None = None) -> tuple[Path, Path]:
    """A private key (``ncfmu-key.pem``) and a self-signed certificate (``ncfmu.der``, 5 years) in ``folder``,
    for ``ncfmu serve --certificate ncfmu.der --private-key ncfmu-key.pem``: ncfmu's application URI, the host's
    name, ``localhost`` and 127.0.0.1 as subject alternative names (OPC UA Part 6 6.2.2). Existing files are
    never overwritten."""
    import socket

    from asyncua.crypto import cert_gen
    from cryptography import x509
    from cryptography.hazmat.primitives.serialization import Encoding
    from cryptography.x509.oid import ExtendedKeyUsageOID

    from ..files import write_atomic
    folder = Path(folder)
    key_path, cert_path = folder / "ncfmu-key.pem", folder / "ncfmu.der"
    for path in (key_path, cert_path):
        if path.exists():
            raise ConfigError("--make-certificate", str(folder), f"{path.name} exists there already (remove it "
                              "first: a key is never overwritten)")
    host = hostname or socket.gethostname()
    key = cert_gen.generate_private_key()
    names: list[x509.GeneralName] = [x509.UniformResourceIdentifier(APPLICATION_URI), x509.DNSName(host),
                                     x509.DNSName("localhost"), x509.IPAddress(ipaddress.ip_address("127.0.0.1"))]
    cert = cert_gen.generate_self_signed_app_certificate(
        key, f"ncfmu serve@{host}", {"organizationName": "ncfmu"}, names,
        extended=[ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH], days=5 * 365)
    folder.mkdir(parents=True, exist_ok=True)
    write_atomic(key_path, cert_gen.dump_private_key_as_pem(key))
    os.chmod(key_path, 0o600)
    write_atomic(cert_path, cert.public_bytes(Encoding.DER))
    return key_path, cert_path
