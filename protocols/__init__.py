"""What goes on the wire: map and delta codecs, messages, key expressions.

Specified language-neutrally in ``PROTOCOL.md``; golden vectors in ``golden/``.
Depends on the core (``polyswarm``), never on agents or the simulator.
"""
