# Sourced: defines `compose` as the Compose v2 plugin (`docker compose`) or, where only the
# standalone tool is installed (Debian's docker-compose package), `docker-compose`, bound to
# deploy/docker-compose.yml and deploy/.env.
if docker compose version >/dev/null 2>&1; then
    compose() { docker compose -p lightfarm -f deploy/docker-compose.yml --env-file deploy/.env "$@"; }
else
    compose() { docker-compose -p lightfarm -f deploy/docker-compose.yml --env-file deploy/.env "$@"; }
fi
