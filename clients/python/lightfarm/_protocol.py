"""The protocol this client speaks: `lightfarm_proto::PROTOCOL_VERSION` of the servers it
was built with (a test checks that the two agree)."""

PROTOCOL_VERSION = 1
