"""rmw_fastrtps publishes asynchronously when the campaign asks for it, never against the user's
own choice."""

from rig_runtime.ros_environment import PUBLICATION_MODE_ENV, asynchronous_publication


def test_asynchronous_unless_the_user_chose_a_mode() -> None:
    assert asynchronous_publication({}) == {PUBLICATION_MODE_ENV: "ASYNCHRONOUS"}
    assert asynchronous_publication({PUBLICATION_MODE_ENV: "SYNCHRONOUS"}) == {}
    assert asynchronous_publication({PUBLICATION_MODE_ENV: "ASYNCHRONOUS"}) == {}
