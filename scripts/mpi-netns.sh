#!/usr/bin/env bash
# Ranks on separate network stacks: runs `rollcam bench --preset PRESET` split across
# RANKS MPI ranks, each in its own network namespace joined to the others by a bridge
# and veth pairs, so that every byte between ranks crosses a real network stack (Open
# MPI's TCP transport, no shared memory). Prints each rank's interface counters beside
# rollcam's own figures (`sent_bytes_per_iteration` x iterations). Needs root (`ip
# netns`) and a build with the `mpi` feature.
# Usage: scripts/mpi-netns.sh [RANKS] [PRESET]     (ROLLCAM_BIN: the binary)
set -euo pipefail
ranks="${1:-2}"
preset="${2:-paper-8x}"
bin="$(realpath "${ROLLCAM_BIN:-target/release/rollcam}")"
warmup=2
iters=10
net=10.77.0
cleanup() {
  for i in $(seq 1 "$ranks"); do ip netns del "rcns$i" 2>/dev/null || true; done
  ip link del rcbr0 2>/dev/null || true
}
trap cleanup EXIT
cleanup
ip link add rcbr0 type bridge
ip addr add "$net.254/24" dev rcbr0
ip link set rcbr0 up
app=()
for i in $(seq 1 "$ranks"); do
  ip netns add "rcns$i"
  ip link add "rch$i" type veth peer name "rcn$i"
  ip link set "rch$i" master rcbr0
  ip link set "rch$i" up
  ip link set "rcn$i" netns "rcns$i"
  ip netns exec "rcns$i" ip addr add "$net.$i/24" dev "rcn$i"
  ip netns exec "rcns$i" ip link set "rcn$i" up
  ip netns exec "rcns$i" ip link set lo up
  [ "$i" -gt 1 ] && app+=(":")
  app+=(-np 1 ip netns exec "rcns$i" "$bin" bench --preset "$preset" --warmup "$warmup" --iters "$iters")
done
counters() { ip netns exec "rcns$1" cat "/sys/class/net/rcn$1/statistics/tx_bytes" "/sys/class/net/rcn$1/statistics/rx_bytes" | paste -sd' '; }
declare -a before
for i in $(seq 1 "$ranks"); do before[$i]="$(counters "$i")"; done
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
# The launcher's own connections (PMIx, out-of-band) must reach the namespaces too.
export PMIX_MCA_ptl_tcp_if_include="$net.0/24" OMPI_MCA_oob_tcp_if_include="$net.0/24"
report="$(mpirun --oversubscribe --mca btl tcp,self --mca btl_tcp_if_include "$net.0/24" -x RAYON_NUM_THREADS=1 "${app[@]}" | grep '^{')"
echo "$report"
echo "rank  interface sent / received (MB)  rollcam sent / received over $((warmup + iters)) iterations (MB)"
for i in $(seq 1 "$ranks"); do
  read -r tx0 rx0 <<<"${before[$i]}"
  read -r tx1 rx1 <<<"$(counters "$i")"
  ours="$(python3 -c "import json,sys; p=json.loads(sys.argv[1])['per_rank'][$i-1]; n=$warmup+$iters; print('%.2f / %.2f' % (p['sent_bytes_per_iteration']*n/1e6, p['received_bytes_per_iteration']*n/1e6))" "$report")"
  printf '%4d  %8.2f / %8.2f                %s\n' "$((i - 1))" "$(echo "($tx1 - $tx0) / 1000000" | bc -l)" "$(echo "($rx1 - $rx0) / 1000000" | bc -l)" "$ours"
done
