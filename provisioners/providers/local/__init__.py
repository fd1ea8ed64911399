"""The `local` provider: real hosts on this machine, as an apache-libcloud NodeDriver.

A network is a bridge inside its own "switch" network namespace; a host is a network
namespace wired to it by a veth pair, an overlay of this machine's "/" (upper dir on a tmpfs
under state_dir) and either systemd booted by systemd-nspawn or tini running sshd, in fresh
PID/mount/UTS/IPC namespaces. Records under state_dir/<prefix>/ let any later driver find,
report and destroy what an earlier one made. Modules: driver (the libcloud API), network and
nodes (lifecycles), host and boot_scripts (boot/stop one host), netns, cgroups, processes,
state, addresses, sweep (leaks without records).

Hosts hide the controller's secrets (hidden paths), get their own /dev, read-only kernel
tunables and fewer capabilities, but they are no security boundary against root inside them
(no user namespace): give untrusted teams machines from a cloud or servers provider.
"""
