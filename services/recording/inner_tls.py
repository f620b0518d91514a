"""The link between ``stb foxglove``'s Origin gate and foxglove-sdk's server behind it, over
TLS with a certificate made when the tool starts and known only to the gate: the inner
server listens on loopback and takes any WebSocket, and a browser lets any page open one to
any port of this machine — a page that found the port once read every channel past the
gate. Now a page's plain ``ws://`` to it fails the TLS handshake, and its ``wss://`` fails
the certificate, which no browser trusts; only the gate, which holds the certificate, gets
through. (foxglove-sdk serves ``wss://`` given ``tls_cert`` and ``tls_key``.)"""

from __future__ import annotations

import datetime
import ipaddress
import ssl
from dataclasses import dataclass

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import NameOID

LOOPBACK = "127.0.0.1"


@dataclass(frozen=True)
class InnerCertificate:
    certificate_pem: bytes
    key_pem: bytes  # PKCS#8

    def client_context(self) -> ssl.SSLContext:
        """What the gate connects with: this certificate and no other, for 127.0.0.1."""
        context = ssl.create_default_context(ssl.Purpose.SERVER_AUTH)
        context.load_verify_locations(cadata=self.certificate_pem.decode("ascii"))
        return context


def make_certificate(days: int = 365) -> InnerCertificate:
    """A fresh self-signed certificate for 127.0.0.1 (P-256), kept in memory only."""
    key = ec.generate_private_key(ec.SECP256R1())
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "stb foxglove inner link")])
    now = datetime.datetime.now(datetime.UTC)
    certificate = (
        x509.CertificateBuilder().subject_name(name).issuer_name(name)
        .public_key(key.public_key()).serial_number(x509.random_serial_number())
        .not_valid_before(now - datetime.timedelta(minutes=5))
        .not_valid_after(now + datetime.timedelta(days=days))
        .add_extension(x509.SubjectAlternativeName([x509.IPAddress(
            ipaddress.ip_address(LOOPBACK))]), critical=False)
        .add_extension(x509.BasicConstraints(ca=True, path_length=None), critical=True)
        .sign(key, hashes.SHA256()))
    return InnerCertificate(
        certificate.public_bytes(serialization.Encoding.PEM),
        key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                          serialization.NoEncryption()))
