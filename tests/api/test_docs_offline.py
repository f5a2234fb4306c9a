"""api.docpages: /docs works on a site without internet access (Swagger UI served from the package)."""

from __future__ import annotations

import re
from collections.abc import Callable
from urllib.parse import urlsplit

from fastapi.testclient import TestClient

from shared.store import MapStore

_REFERENCES = re.compile(r"""(?:src|href)\s*=\s*["']([^"']+)["']|url:\s*'([^']+)'""")


def _references(html: str) -> list[str]:
    return [first or second for first, second in _REFERENCES.findall(html)]


def test_docs_page_names_no_other_host_and_its_assets_are_served(client: TestClient) -> None:
    page = client.get("/docs")

    assert page.status_code == 200
    references = _references(page.text)
    assert any(ref.endswith(".js") for ref in references) and any(ref.endswith(".css") for ref in references)
    assert [ref for ref in references if urlsplit(ref).netloc or ref.startswith("//")] == []
    for ref in references:
        asset = client.get(ref)
        assert asset.status_code == 200, ref
        assert asset.content, ref
    assert "SwaggerUIBundle" in client.get(next(r for r in references if r.endswith("bundle.js"))).text


def test_docs_page_needs_no_key_where_reads_do(store: MapStore, make_client: Callable[..., TestClient]) -> None:
    client = make_client(store, require_keys_for_reads=True)
    page = client.get("/docs")

    assert client.get("/v1/maps").status_code == 401
    assert page.status_code == 200
    assert all(client.get(ref).status_code == 200 for ref in _references(page.text))


def test_redoc_is_not_offered_from_a_cdn(client: TestClient) -> None:
    assert client.get("/redoc").status_code == 404
