"""The QoS policies a params file may override on the node's publishers (``qos_overrides``).

As in rclcpp drivers, ``qos_overrides.<topic>.publisher.<policy>`` parameters set the QoS of
``joint_states``, ``~/status`` and ``/diagnostics`` at start-up, e.g.
``qos_overrides./joint_states.publisher.reliability: best_effort``. rclpy's
``QoSOverridingOptions.with_default_policies()`` offers history, depth and reliability only;
durability is added so that a late-joining subscriber can be served (``transient_local``).
rclpy declares each as a read-only parameter holding the value in force; an unknown policy
value stops the start with a ConfigError naming the topic, the policy, the value and the values
allowed. The recorder offers the profile in force (``pub.qos_profile``), so a bag's
``offered_qos_profiles`` match.
"""

from __future__ import annotations

from typing import Any

from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import QoSPolicyKind
from rclpy.qos_overriding_options import InvalidQosOverridesError, QoSOverridingOptions

from ssi_bridge.exceptions import ConfigError

#: the overridable policies of the node's publishers
POLICIES = (QoSPolicyKind.HISTORY, QoSPolicyKind.DEPTH, QoSPolicyKind.RELIABILITY,
            QoSPolicyKind.DURABILITY)


#: the topics of the publishers that take overrides (``_create_ros_side`` of the node)
TOPICS = ("joint_states", "~/status", "/diagnostics")
PREFIX = "qos_overrides."

#: the values a policy override may take (rclpy's enum names, lower case)
ALLOWED = ("reliability: reliable | best_effort; durability: volatile | transient_local; "
           "history: keep_last | keep_all; depth: an integer")


def overridable_publisher(node: Node, msg_type: type[Any], topic: str,
                          depth: int = 10) -> Publisher:
    """``node.create_publisher(msg_type, topic, depth)`` whose :data:`POLICIES` a params file
    overrides with ``qos_overrides.<topic>.publisher.*``.

    Raises ConfigError for a policy value rclpy does not know (rclpy raises RuntimeError).
    """
    try:
        return node.create_publisher(
            msg_type, topic, depth,
            qos_overriding_options=QoSOverridingOptions(policy_kinds=POLICIES))
    except (RuntimeError, InvalidQosOverridesError) as err:
        raise ConfigError(f"qos_overrides of {node.resolve_topic_name(topic)}: {err} "
                          f"({ALLOWED})") from None


def stray_overrides(node: Node, given: list[str]) -> list[str]:
    """One line per ``qos_overrides.*`` name in ``given`` that no publisher of the node takes
    (a topic or policy misspelt, or a topic without overrides such as ``~/events``): rclpy
    would ignore it without a word."""
    topics = [node.resolve_topic_name(t) for t in TOPICS]
    wanted = {f"{PREFIX}{t}.publisher.{p.name.lower()}" for t in topics for p in POLICIES}
    usage = (f"{PREFIX}<{' | '.join(topics)}>.publisher."
             f"<{' | '.join(p.name.lower() for p in POLICIES)}>")
    return [f"parameter '{name[:120]}' is no QoS override of this node and is ignored; "
            f"it takes {usage}" for name in sorted(given)
            if name.startswith(PREFIX) and name not in wanted]


__all__ = ["ALLOWED", "POLICIES", "TOPICS", "overridable_publisher", "stray_overrides"]
