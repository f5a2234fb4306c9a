FROM python:3.11-slim
WORKDIR /opt/aisle
COPY pyproject.toml README.md ./
COPY shared ./shared
COPY services ./services
COPY atlas ./atlas
COPY api ./api
COPY migrations ./migrations
RUN pip install --no-cache-dir .
USER nobody
ENTRYPOINT ["aisle"]
