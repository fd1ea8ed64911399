"""The shell scripts that boot a host, run by bash with their parameters as arguments."""

# Runs outside the host's root (in the launcher's private mount namespace), on first boot only:
# later boots (reboot_node) must not trust paths the host itself may have replaced by symlinks.
FIRST_BOOT = r"""
first_boot() {
  local root=$1 hostname=$2 machine_id=$3 authorized_keys=$4
  shift 4
  local marker=$root/var/lib/cloudsim-local-first-boot
  [ -e "$marker" ] && return 0
  printf '%s\n' "$hostname" > "$root/etc/hostname"
  printf '%s\n' "$machine_id" > "$root/etc/machine-id"
  printf '127.0.0.1\tlocalhost\n127.0.1.1\t%s\n' "$hostname" > "$root/etc/hosts"
  rm -f "$root"/etc/ssh/ssh_host_*
  # Own host keys; no RSA key: it costs ~0.5 s of CPU per host and modern clients never need it.
  local key_type
  for key_type in ed25519 ecdsa; do
    ssh-keygen -q -t "$key_type" -N '' -C "root@$hostname" \
      -f "$root/etc/ssh/ssh_host_${key_type}_key"
  done
  install -d -m 755 "$root/etc/ssh/sshd_config.d"
  printf 'HostKey /etc/ssh/ssh_host_%s_key\n' ed25519 ecdsa \
    > "$root/etc/ssh/sshd_config.d/cloudsim-host-keys.conf"
  install -d -m 700 "$root/root/.ssh"
  # /root is hidden from the host (see hide_paths): give root its stock dotfiles back.
  local dotfile
  for dotfile in bashrc profile; do
    if [ -e "/usr/share/base-files/dot.$dotfile" ] && [ ! -e "$root/root/.$dotfile" ]; then
      install -m 644 "/usr/share/base-files/dot.$dotfile" "$root/root/.$dotfile"
    fi
  done
  install -m 600 "$authorized_keys" "$root/root/.ssh/authorized_keys"
  local unit
  for unit in "$@"; do ln -sfn /dev/null "$root/etc/systemd/system/$unit"; done
  touch "$marker"
}
"""

MOUNT_OVERLAY = r"""
root=$host_dir/root
lower=/
# image layers (layers.py) stacked above "/", fixed when the host was created
if [ -s "$host_dir/lowerdir" ]; then lower=$(cat "$host_dir/lowerdir"); fi
mount -t overlay "$machine" \
  -o "lowerdir=$lower,upperdir=$host_dir/upper,workdir=$host_dir/work" "$root"
"""

# PID 1 of fresh mount/UTS/IPC/PID namespaces, already inside the host's network namespace.
MINIMAL_INIT = (
    "set -euo pipefail\n"
    + "DROPPED_CAPABILITIES=-mknod,-dac_read_search,-sys_module,-sys_rawio,-sys_time,-sys_boot\n"
    + FIRST_BOOT
    + "host_dir=$1 hostname=$2 machine=$3 machine_id=$4 authorized_keys=$5\n"
    + MOUNT_OVERLAY
    + r"""
first_boot "$root" "$hostname" "$machine_id" "$authorized_keys"
mount -t proc proc "$root/proc"
# Like nspawn: kernel tunables read-only, only this host's network ones (ip_forward) writable.
mount --bind "$root/proc/sys" "$root/proc/sys"
mount -o remount,bind,ro "$root/proc/sys"
mount --bind /proc/sys/net "$root/proc/sys/net"
mount -t sysfs -o ro sysfs "$root/sys"
# A /dev of its own: the machine's disks must not be reachable from inside.
mount -t tmpfs -o mode=755,nosuid tmpfs "$root/dev"
for node in null:1:3 zero:1:5 full:1:7 random:1:8 urandom:1:9 tty:5:0; do
  IFS=: read -r name major minor <<< "$node"
  mknod -m 666 "$root/dev/$name" c "$major" "$minor"
done
install -d -m 755 "$root/dev/net" "$root/dev/pts" "$root/dev/shm"
mknod -m 600 "$root/dev/net/tun" c 10 200
mount -t devpts -o newinstance,ptmxmode=0666,mode=0620,gid=5 devpts "$root/dev/pts"
ln -s pts/ptmx "$root/dev/ptmx"
mount -t tmpfs -o mode=1777,nosuid,nodev tmpfs "$root/dev/shm"
ln -s /proc/self/fd "$root/dev/fd"
ln -s /proc/self/fd/0 "$root/dev/stdin"
ln -s /proc/self/fd/1 "$root/dev/stdout"
ln -s /proc/self/fd/2 "$root/dev/stderr"
mount -t tmpfs -o mode=755 tmpfs "$root/run"
mount -t tmpfs -o mode=1777 tmpfs "$root/tmp"
install -d -m 755 "$root/run/sshd"
hostname "$hostname"
# pivot_root, not chroot: root inside could simply chroot back out of a chroot.
install -d -m 700 "$root/run/old-root"
cd "$root"
pivot_root . run/old-root
cd /
umount --lazy /run/old-root
rmdir /run/old-root
exec setpriv --bounding-set "$DROPPED_CAPABILITIES" -- /usr/bin/tini -s -- /usr/sbin/sshd -D -e
"""
)

# Runs in a private mount namespace, so the overlay and nspawn's propagation directory vanish
# with the host instead of lingering in the root mount table.
SYSTEMD_BOOT = (
    "set -euo pipefail\n"
    + FIRST_BOOT
    + "host_dir=$1 hostname=$2 machine=$3 machine_id=$4 authorized_keys=$5 netns=$6\n"
    + "shift 6\n"
    + MOUNT_OVERLAY
    + r"""
first_boot "$root" "$hostname" "$machine_id" "$authorized_keys" "$@"
propagate=/run/systemd/nspawn/propagate
mkdir -p "$propagate"
mount -t tmpfs -o mode=700 "$machine-propagate" "$propagate"
tun=()
if [ -c /dev/net/tun ]; then tun=(--bind=/dev/net/tun); fi
exec systemd-nspawn --quiet --directory="$root" --boot --machine="$machine" \
  --hostname="$hostname" --register=no --keep-unit --console=passive \
  --capability=CAP_NET_ADMIN --drop-capability=CAP_MKNOD,CAP_DAC_READ_SEARCH "${tun[@]}" \
  --network-namespace-path="/run/netns/$netns"
"""
)

# Records the launcher's PID (as seen from the root namespace) and moves it into the host's
# own cgroups (see cgroups.py) before becoming the launcher.
LAUNCHER = r"""
set -eu
printf '%s\n' "$$" > "$1"
cgroup_count=$2
shift 2
while [ "$cgroup_count" -gt 0 ]; do
  mkdir -p "$1"
  printf '%s\n' "$$" > "$1/cgroup.procs"
  shift
  cgroup_count=$((cgroup_count - 1))
done
exec "$@"
"""
