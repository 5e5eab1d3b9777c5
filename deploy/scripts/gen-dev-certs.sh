#!/usr/bin/env bash
# A development CA, TLS certificates, passwords and the router's config for the secured ASNN
# fleet (deploy/zenoh/secure/, docs/operations.md). Nothing it writes is committed: the default
# output directory, deploy/secrets/, is git-ignored. For development and tests only: a real
# deployment gets its certificates from the site's own CA and keeps the keys out of images.
#
#   deploy/scripts/gen-dev-certs.sh [--robots ID,ID,...] [OUT_DIR] [HOST...]
#
# --robots (default robot1): the robot ids whose cameras get an identity of their own.
# OUT_DIR (default deploy/secrets, made mode 700) receives:
#   ca.pem, ca.key        the development CA (ca.key stays here: no identity's folder holds it)
#   router/               what the router needs: ca.pem, router.pem and router.key (CN router;
#                         SAN localhost, 127.0.0.1, router and every HOST given: the names other
#                         machines reach the router by), credentials.txt (user:password per
#                         line, the usrpwd dictionary) and router.json5 (the template
#                         deploy/zenoh/secure/router.json5 with one subject, rule and policy
#                         per camera)
#   <name>/               one folder per client identity, holding only its own: ca.pem,
#                         <name>.pem, <name>.key (CN = name) and <name>.json5, its client config
#                         (user, password, CA, certificate)
# with the identities worker, dashboard, alerts, foxglove and camera-<robot> for each robot id:
# user name and certificate CN are the same, and the router's access control requires both, so
# a camera may publish only <prefix>/<its robot>/frame and .../preview. Each folder is mounted
# alone into its service's container (deploy/compose.secure.yml). Inside OUT_DIR's 700, what is
# secret is readable by the user who ran the script only (mode 600: the keys, credentials.txt
# and the client configs, which hold the passwords); the certificates and router.json5 are 644,
# the folders 755. A process reading them as another user cannot: deploy/compose.secure.yml
# runs its containers as this user (ASNN_UID, ASNN_GID), and a systemd unit's user must own its
# folder (docs/operations.md, "Secrets on disk").
#
# A HOST is a DNS name or an IP address (python3 checks the addresses; [fd00::2] as in an
# endpoint is taken too). Run again (to add a robot, or a HOST: give every robot id and every
# HOST each time), it keeps the CA and every identity whose certificate is valid for 30 more
# days (a third of its validity where that is shorter), with its password, so the configs
# already deployed stay valid; it issues what is new or expiring (a renewed identity keeps its
# password; one whose folder was deleted, to revoke it, gets a new one), and the router's
# certificate and config each time (warning where the certificate no longer names a host the
# previous one did). A robot left out can no longer connect (its folder is named, to delete).
# Certificates are valid for ASNN_CERT_DAYS days (365); the CA for ten times that. The configs
# name the files by their path in OUT_DIR, or under ASNN_SECRETS_PATH when set: where each
# folder is mounted in containers (ASNN_SECRETS_PATH=/etc/asnn/secrets for
# deploy/compose.secure.yml).
set -euo pipefail
if [[ ${1:-} == -h || ${1:-} == --help ]]; then
  sed -n '2,/^set -euo/p' "$0" | sed '$d; s/^# \{0,1\}//'
  exit 0
fi

robots=(robot1)
if [[ ${1:-} == --robots ]]; then
  IFS=, read -ra robots <<< "${2:-}"
  shift 2 || { echo "gen-dev-certs: --robots needs a list of robot ids" >&2; exit 2; }
fi
for robot in "${robots[@]}"; do
  [[ $robot =~ ^[A-Za-z0-9_-]{1,64}$ ]] || {
    echo "gen-dev-certs: invalid robot id '$robot': use 1 to 64 of A-Z a-z 0-9 _ -" >&2; exit 2; }
done
(( ${#robots[@]} )) || { echo "gen-dev-certs: --robots needs at least one robot id" >&2; exit 2; }
# each id once: a repeated one would repeat its identity and the router's rule ids
mapfile -t robots < <(printf '%s\n' "${robots[@]}" | awk '!seen[$0]++')
out=${1:-deploy/secrets}
shift || true
hosts=("$@")
template=$(cd "$(dirname "$0")/../zenoh/secure" && pwd)/router.json5
names=(worker dashboard alerts foxglove)
for robot in "${robots[@]}"; do names+=("camera-$robot"); done
days=${ASNN_CERT_DAYS:-365}
[[ $days =~ ^[1-9][0-9]{0,4}$ ]] && (( days <= 36500 )) || {
  echo "gen-dev-certs: ASNN_CERT_DAYS must be a whole number of days, 1 to 36500 (not '$days')" >&2
  exit 2; }
# checked before anything is written: a name openssl refuses would leave a half-made folder,
# and a comma would add names of its own to the router's certificate
for i in "${!hosts[@]}"; do
  host=${hosts[i]}
  [[ $host =~ ^\[(.*)\]$ ]] && host=${BASH_REMATCH[1]}  # [fd00::2], as in an endpoint
  if [[ $host =~ ^[0-9.]+$ || $host == *:* ]]; then  # an address: one a machine can have
    python3 -c 'import ipaddress, sys; a = ipaddress.ip_address(sys.argv[1])
sys.exit(a.is_unspecified or a.is_multicast)' "$host" 2>/dev/null || {
      echo "gen-dev-certs: invalid host '$host': not an address a router can have" >&2; exit 2; }
    hosts[i]="IP:$host"
  elif [[ $host =~ ^[A-Za-z0-9]([A-Za-z0-9-]{0,62})(\.[A-Za-z0-9]([A-Za-z0-9-]{0,62}))*$ ]]; then
    hosts[i]="DNS:$host"
  else
    echo "gen-dev-certs: invalid host '$host': give a DNS name or an IP address" >&2
    exit 2
  fi
done

# the configs name files by these paths inside JSON5 strings: a quote, a backslash or a line
# break would end or escape the string (OUT_DIR's whole path, as `cd` then `pwd` give it:
# the configs name it so)
paths_ok() { [[ $1 != *[\"\\]* && $1 != *$'\n'* ]]; }
whole=$out
[[ $whole == /* ]] || whole=$PWD/$out
paths_ok "${ASNN_SECRETS_PATH:-}" && paths_ok "$whole" || {
  echo "gen-dev-certs: OUT_DIR and ASNN_SECRETS_PATH cannot hold a quote (\"), a backslash or a" \
    "line break: the configs name their files inside JSON5 strings" >&2; exit 2; }

command -v openssl >/dev/null || { echo "gen-dev-certs: openssl is required" >&2; exit 2; }
mkdir -p "$out"
cd "$out"
chmod 700 .  # the folder written to (a link/.. in OUT_DIR: mkdir and cd resolve it otherwise)
umask 077  # every file private as it is written; the certificates are opened to 644 below
top=$(pwd)
# a certificate valid for less than this more is issued again: 30 days, or a third of a
# shorter validity (else every run would reissue every identity)
renew=$(( (days < 90 ? days / 3 : 30) * 86400 ))

where() {  # where NAME: the path the configs of NAME's folder name its files by
  echo "${ASNN_SECRETS_PATH:-$top/$1}"
}

ssl() {  # ssl ARGS...: openssl, quiet unless it fails, then its own words and exit 1
  local said
  said=$(openssl "$@" 2>&1) || {
    echo "gen-dev-certs: openssl $1 failed:" >&2
    printf '%s\n' "$said" | grep -v '^[.+*]*$' >&2
    exit 1
  }
}

valid() {  # valid CERT: signed by this CA and valid for $renew seconds more
  [[ -f $1 ]] && openssl verify -CAfile ca.pem "$1" >/dev/null 2>&1 \
    && openssl x509 -in "$1" -noout -checkend "$renew" >/dev/null 2>&1
}

if [[ -f ca.key && -f ca.pem ]] && openssl x509 -in ca.pem -noout -checkend "$renew" \
    >/dev/null 2>&1; then
  echo "gen-dev-certs: keeping the CA in $top" >&2
else
  ssl req -x509 -newkey rsa:2048 -nodes -sha256 -days "$(( days * 10 ))" \
    -subj "/CN=asnn development CA" -keyout ca.key -out ca.pem \
    -addext "basicConstraints=critical,CA:TRUE" -addext "keyUsage=critical,keyCertSign,cRLSign"
fi
chmod 600 ca.key
chmod 644 ca.pem

issue() {  # issue NAME EXTENSIONS...: NAME/NAME.pem and NAME/NAME.key
  local name=$1; shift
  local ext
  ext=$(mktemp)
  printf '%s\n' "$@" > "$ext"
  ssl req -newkey rsa:2048 -nodes -sha256 -subj "/CN=$name" -keyout "$name/$name.key" \
    -out "$name/$name.csr"
  ssl x509 -req -in "$name/$name.csr" -CA ca.pem -CAkey ca.key -CAcreateserial \
    -days "$days" -sha256 -extfile "$ext" -out "$name/$name.pem"
  rm -f "$name/$name.csr" "$ext" ca.srl
}

folder() {  # folder NAME: NAME/ with the CA's certificate
  mkdir -p "$1"
  chmod 755 "$1"
  cp ca.pem "$1/ca.pem"
}

san="DNS:localhost,IP:127.0.0.1,DNS:router"
for host in "${hosts[@]}"; do san+=",$host"; done
old_san=""
[[ -f router/router.pem ]] && old_san=$(openssl x509 -in router/router.pem -noout \
  -ext subjectAltName 2>/dev/null | tail -n +2) || true
folder router
issue router "basicConstraints=CA:FALSE" "keyUsage=digitalSignature,keyEncipherment" \
  "extendedKeyUsage=serverAuth,clientAuth" "subjectAltName=$san"
# the router's certificate is issued from this run's HOSTs only: a name the old one had and
# this one lacks (a run to add a robot that left the HOSTs out) refuses the clients that reach
# the router by it, once the router restarts
dropped=$(python3 - "$old_san" "$san" <<'PY'
import ipaddress, sys

def names(text):
    found = set()
    for part in text.replace("IP Address:", "IP:").split(","):
        kind, _, value = part.strip().partition(":")
        if kind == "IP":
            try:
                value = str(ipaddress.ip_address(value))
            except ValueError:
                pass
        if kind in ("DNS", "IP"):
            found.add(f"{kind}:{value}")
    return found

print(" ".join(sorted(names(sys.argv[1]) - names(sys.argv[2]))))
PY
)
[[ -z $dropped ]] || echo "gen-dev-certs: WARNING: the router's new certificate no longer" \
  "names $dropped (the old one did): clients that reach the router by that name are refused" \
  "once it restarts; give every HOST on each run" >&2

old_credentials=""
[[ -f router/credentials.txt ]] && old_credentials=$(cat router/credentials.txt)
credentials=""
kept=() issued=()
for name in "${names[@]}"; do
  folder "$name"
  password=$(printf '%s\n' "$old_credentials" | sed -n "s/^$name:\([0-9a-f]\{32\}\)$/\1/p")
  if [[ -n $password && -f $name/$name.key ]] && valid "$name/$name.pem"; then
    kept+=("$name")
  else
    # an identity renewed (its key still here, its certificate expiring or gone) keeps its
    # password: installing its new certificate and key alone keeps working with the router's
    # new credentials.txt; one whose folder or key was deleted (to revoke a leaked copy: there
    # is no revocation list) gets a new password, which locks the old copy out
    [[ -f $name/$name.key ]] || password=""
    issue "$name" "basicConstraints=CA:FALSE" "keyUsage=digitalSignature,keyEncipherment" \
      "extendedKeyUsage=clientAuth" "subjectAltName=DNS:$name"
    [[ -n $password ]] || password=$(openssl rand -hex 16)
    issued+=("$name")
  fi
  credentials+="$name:$password"$'\n'
  dir=$(where "$name")
  cat > "$name/$name.json5" <<JSON
// generated by deploy/scripts/gen-dev-certs.sh: the identity $name of the secured fleet
{
  mode: "client",
  scouting: { multicast: { enabled: false }, gossip: { enabled: false } },
  transport: {
    auth: { usrpwd: { user: "$name", password: "$password" } },
    link: {
      tls: {
        root_ca_certificate: "$dir/ca.pem",
        // the client certificate: the router requires it (mTLS) and matches its CN
        enable_mtls: true,
        connect_certificate: "$dir/$name.pem",
        connect_private_key: "$dir/$name.key",
      },
      tx: { lease: 1000, keep_alive: 4 },
    },
    // no shared memory: a closed session's pool stays mapped in its peers (docs/operations.md)
    shared_memory: { enabled: false },
  },
}
JSON
done
printf '%s' "$credentials" > router/credentials.txt

# the router's config: the template, its secrets' paths, one identity and rule per camera
rules="" subjects="" policies=""
for robot in "${robots[@]}"; do
  rules+="      { id: \"camera-$robot-publish\", permission: \"allow\", flows: [\"ingress\"],"
  rules+=" messages: [\"put\"], key_exprs: [\"asnn/$robot/frame\", \"asnn/$robot/preview\"] },"$'\n'
  rules+="      { id: \"camera-$robot-announce\", permission: \"allow\", flows: [\"ingress\"],"
  rules+=" messages: [\"liveliness_token\"], key_exprs: [\"asnn/@camera/$robot\"] },"$'\n'
  rules+="      { id: \"camera-$robot-refusals-in\", permission: \"allow\", flows: [\"ingress\"],"
  rules+=" messages: [\"declare_subscriber\"], key_exprs: [\"asnn/$robot/refused\"] },"$'\n'
  rules+="      { id: \"camera-$robot-refusals-out\", permission: \"allow\", flows: [\"egress\"],"
  rules+=" messages: [\"put\"], key_exprs: [\"asnn/$robot/refused\"] },"$'\n'
  subjects+="      { id: \"camera-$robot\", usernames: [\"camera-$robot\"],"
  subjects+=" cert_common_names: [\"camera-$robot\"] },"$'\n'
  policies+="      { subjects: [\"camera-$robot\"], rules: [\"camera-$robot-publish\","
  policies+=" \"camera-$robot-announce\", \"camera-$robot-refusals-in\","
  policies+=" \"camera-$robot-refusals-out\", \"camera-matching\"] },"$'\n'
done
dir=$(where router)
{
  echo "// generated by deploy/scripts/gen-dev-certs.sh from deploy/zenoh/secure/router.json5"
  echo "// for the cameras of ${robots[*]}; its files are in $dir"
  header=1  # the template's own header describes the template: left out
  while IFS= read -r line; do
    if (( header )) && [[ $line == //* ]]; then continue; fi
    header=0
    case $line in
      *"// @cameras rules"*) printf '%s' "$rules" ;;
      *"// @cameras subjects"*) printf '%s' "$subjects" ;;
      *"// @cameras policies"*) printf '%s' "$policies" ;;
      # "$dir" quoted: an & in it is itself (bash 5.2's patsub_replacement read it as the match)
      *) printf '%s\n' "${line//\/etc\/asnn\/secrets/"$dir"}" ;;
    esac
  done < "$template"
} > router/router.json5

# inside OUT_DIR's 700: certificates and the router's config readable by any user, secrets
# (keys, passwords, the client configs that hold them) by the owner only (umask 077 above made
# every file so as it was written)
for name in router "${names[@]}"; do
  chmod 644 "$name"/*.pem
  chmod 600 "$name"/*.key
done
chmod 644 router/router.json5
chmod 600 router/credentials.txt
for name in "${names[@]}"; do chmod 600 "$name/$name.json5"; done
for folder in */; do  # an identity left out of this run can no longer connect: say so
  folder=${folder%/}
  [[ $folder == router || " ${names[*]} " == *" $folder "* ]] && continue
  [[ -f $folder/$folder.json5 ]] && echo "gen-dev-certs: $top/$folder/ is no longer an" \
    "identity of the router (its credentials are refused): delete it" >&2
done
echo "gen-dev-certs: in $top: router/ and the identities ${names[*]}" \
  "(issued: ${issued[*]:-none}; kept: ${kept[*]:-none})" >&2
