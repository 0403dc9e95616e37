"""Zenoh configurations of a secured fleet: TLS (or mTLS), user/password, and an
access-control list confining each robot to its own key prefix.

Zenoh 1.10 ACL rules cannot be templated per user, so the router's list has one rule
per robot; ``router_config`` writes it for a list of robot ids (``polyswarm fleet
router-config``). Robots and the coordinator authenticate with ``usrpwd``; the ACL
matches them by user name.

What a robot ``rN`` may send into the router (ingress): puts under
``polyswarm/<swarm>/robots/rN/**``, its map queryable and replies there, its liveliness
token ``polyswarm/<swarm>/alive/agent/rN``, and subscriptions and queries anywhere
under the swarm. The coordinator may do anything under the swarm. Everything else is
denied; what the router forwards to its clients (egress) is allowed under the swarm.
"""

from __future__ import annotations

from protocols.keys import ROOT, check_name

READ_MESSAGES = ["declare_subscriber", "query", "declare_liveliness_subscriber", "liveliness_query"]
ALL_MESSAGES = [
    "put",
    "delete",
    "declare_subscriber",
    "query",
    "reply",
    "declare_queryable",
    "liveliness_token",
    "declare_liveliness_subscriber",
    "liveliness_query",
]


def acl(swarm: str, robots: list[str], coordinator_user: str = "coordinator") -> dict:
    check_name(swarm, "swarm")
    prefix = f"{ROOT}/{swarm}"
    rules = [
        {
            "id": "forward-swarm",
            "permission": "allow",
            "flows": ["egress"],
            "messages": ALL_MESSAGES,
            "key_exprs": [f"{prefix}/**"],
        },
        {
            "id": "read-swarm",
            "permission": "allow",
            "flows": ["ingress"],
            "messages": READ_MESSAGES,
            "key_exprs": [f"{prefix}/**"],
        },
        {
            "id": "coordinator-all",
            "permission": "allow",
            "flows": ["ingress"],
            "messages": ALL_MESSAGES,
            "key_exprs": [f"{prefix}/**"],
        },
    ]
    subjects = [{"id": "coordinator", "usernames": [coordinator_user]}]
    policies = [{"rules": ["forward-swarm", "coordinator-all"], "subjects": ["coordinator"]}]
    for rid in robots:
        check_name(rid, "robot id")
        rules.append(
            {
                "id": f"own-{rid}",
                "permission": "allow",
                "flows": ["ingress"],
                "messages": ["put", "delete", "declare_queryable", "reply", "liveliness_token"],
                "key_exprs": [f"{prefix}/robots/{rid}/**", f"{prefix}/alive/agent/{rid}"],
            }
        )
        subjects.append({"id": f"robot-{rid}", "usernames": [rid]})
        policies.append(
            {"rules": ["forward-swarm", "read-swarm", f"own-{rid}"], "subjects": [f"robot-{rid}"]}
        )
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    }


def router_config(
    swarm: str,
    robots: list[str],
    listen: str = "tls/0.0.0.0:7447",
    users_file: str = "/etc/polyswarm/users.txt",
    tls: dict | None = None,
) -> dict:
    """The coordinator's (router's) config: listen, TLS files, users, ACL.

    ``tls``: {"root_ca_certificate", "listen_certificate", "listen_private_key",
    "enable_mtls"}; None for plain TCP (development only)."""
    transport: dict = {
        "auth": {
            "usrpwd": {
                "user": "coordinator",
                "password": "",  # set here or leave empty when the router only checks
                "dictionary_file": users_file,
            }
        }
    }
    if tls:
        transport["link"] = {"tls": tls}
    transport["link"] = transport.get("link", {}) | {"tx": {"lease": 3000, "keep_alive": 4}}
    return {
        "mode": "router",
        "listen": {"endpoints": [listen]},
        "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}},
        "transport": transport,
        "access_control": acl(swarm, robots),
    }


def client_config(connect: str, user: str, password: str, tls: dict | None = None) -> dict:
    """A robot's (or the coordinator's) client config for the secured router."""
    transport: dict = {"auth": {"usrpwd": {"user": user, "password": password}}}
    if tls:
        transport["link"] = {"tls": tls}
    return {
        "mode": "client",
        "connect": {"endpoints": [connect]},
        "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}},
        "transport": transport,
    }
