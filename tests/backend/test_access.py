"""Access: one pilot, the token, explicit hand-over (a request lapses, and never takes
control when the pilot goes), wrong-token limits per page and per address (never for
everyone)."""

from __future__ import annotations

import pytest
from support import FakeClock

from ucat_console.backend.access import LOCAL, AccessControl, AccessDenied
from ucat_console.backend.access import AccessConfig

TOKEN = "correct-horse-battery"


@pytest.fixture
def clock() -> FakeClock:
    return FakeClock(100.0)


@pytest.fixture
def access(clock: FakeClock) -> AccessControl:
    a = AccessControl(AccessConfig(token=TOKEN, max_failures=3, lockout=30.0), clock=clock)
    for c in (1, 2, 3):
        a.connect(c)
    return a


def test_random_tokens_differ_and_a_fixed_one_is_kept() -> None:
    a, b = AccessControl(), AccessControl()
    assert a.token != b.token and len(a.token) >= 16
    assert AccessControl(AccessConfig(token=TOKEN)).token == TOKEN


def test_right_token_makes_the_first_client_pilot(access: AccessControl) -> None:
    assert access.pilot is None
    assert access.request_control(1, TOKEN) is True
    assert access.pilot == 1
    assert access.is_pilot(1) and not access.is_pilot(2)


def test_wrong_token_or_wrong_type_is_refused(access: AccessControl) -> None:
    for bad in ("wrong", "", None, 12345, TOKEN + "x"):
        with pytest.raises(AccessDenied):
            access.request_control(1, bad)
    assert access.pilot is None


def test_taking_control_from_a_pilot_needs_the_pilots_hand_over(access: AccessControl) -> None:
    access.request_control(1, TOKEN)
    assert access.request_control(2, TOKEN) is False  # waits
    assert access.pilot == 1 and access.pending == 2
    with pytest.raises(AccessDenied):
        access.hand_over(2, 2)  # the asker cannot hand over to itself
    with pytest.raises(AccessDenied):
        access.hand_over(1, 3)  # client 3 did not ask
    access.hand_over(1, 2)
    assert access.pilot == 2 and access.pending is None


def test_decline_keeps_the_pilot(access: AccessControl) -> None:
    access.request_control(1, TOKEN)
    access.request_control(2, TOKEN)
    access.decline(1)
    assert access.pilot == 1 and access.pending is None
    with pytest.raises(AccessDenied):
        access.hand_over(1, 2)


def test_require_pilot_refuses_viewers_and_allows_the_console(access: AccessControl) -> None:
    access.request_control(1, TOKEN)
    access.require_pilot(1, "arm")
    access.require_pilot(LOCAL, "arm")
    with pytest.raises(AccessDenied, match="read-only"):
        access.require_pilot(2, "arm")


def test_pilot_leaving_leaves_nobody_in_control(access: AccessControl) -> None:
    access.request_control(1, TOKEN)
    assert access.disconnect(3) is False
    assert access.disconnect(1) is True
    assert access.pilot is None
    assert access.request_control(2, TOKEN) is True


def test_release_only_by_the_pilot(access: AccessControl) -> None:
    access.request_control(1, TOKEN)
    with pytest.raises(AccessDenied):
        access.release(2)
    access.release(1)
    assert access.pilot is None


def test_wrong_tokens_lock_only_the_page_that_sent_them(access: AccessControl, clock: FakeClock) -> None:
    for _ in range(3):
        with pytest.raises(AccessDenied, match="wrong"):
            access.request_control(2, "guess")
    with pytest.raises(AccessDenied, match="locked"):
        access.request_control(2, TOKEN)  # this page: locked, even with the right token
    assert access.request_control(3, TOKEN) is True  # another page gets in at once
    clock.advance(31.0)
    access.release(3)
    assert access.request_control(2, TOKEN) is True  # the lock ends


def test_reloaded_pages_get_no_more_guesses_once_their_address_is_locked(clock: FakeClock) -> None:
    a = AccessControl(AccessConfig(token=TOKEN, max_failures=3, address_max_failures=5, lockout=30.0),
                      clock=clock)
    a.connect(7, "127.0.0.1")
    assert a.request_control(7, TOKEN) is True  # the pilot, flying from the same machine
    spam = iter(range(100, 10_000))
    guesses = 0
    for _ in range(40):  # reload after reload from one machine, wrong tokens each time
        page = next(spam)
        a.connect(page, "127.0.0.1")
        for _ in range(3):
            try:
                a.request_control(page, "guess")
            except AccessDenied as e:
                guesses += str(e).endswith("wrong pilot token")
        a.disconnect(page)
        clock.advance(0.1)
    assert guesses == 5  # the address's budget, however many pages it opened
    assert a.pilot == 7  # the pilot in control needs no token: nothing changes for it
    a.connect(8, "127.0.0.1")  # a fresh page of the locked address: told how long
    with pytest.raises(AccessDenied, match=r"127\.0\.0\.1.*another 2\d s"):
        a.request_control(8, TOKEN)
    a.connect(9, "10.0.0.8")  # other addresses are not touched
    assert a.request_control(9, TOKEN) is False  # (it waits for the pilot's hand-over)
    clock.advance(30.0)
    a.release(7)
    assert a.request_control(8, TOKEN) is True  # the lock ends


def test_an_address_over_its_limit_locks_every_page_of_it(clock: FakeClock) -> None:
    a = AccessControl(AccessConfig(token=TOKEN, max_failures=10, address_max_failures=4, lockout=30.0),
                      clock=clock)
    for c in (1, 2, 3):
        a.connect(c, "10.0.0.9")
    a.connect(4, "10.0.0.8")
    for c in (1, 2):
        for _ in range(2):
            with pytest.raises(AccessDenied, match="wrong"):
                a.request_control(c, "guess")
    with pytest.raises(AccessDenied, match="10.0.0.9"):
        a.request_control(1, TOKEN)  # failed before, its address is over its limit
    with pytest.raises(AccessDenied, match="10.0.0.9"):
        a.request_control(3, TOKEN)  # a page that had not failed: no guess either
    assert a.request_control(4, TOKEN) is True  # other addresses are not touched


def test_a_request_waiting_when_the_pilot_goes_never_takes_control(access: AccessControl) -> None:
    assert access.request_control(1, TOKEN) is True
    assert access.request_control(2, TOKEN) is False  # waits for 1's hand-over
    assert access.disconnect(1) is True
    assert access.pilot is None and access.pending is None
    assert access.request_control(3, TOKEN) is True  # the token, after the pilot is gone: at once


def test_a_request_the_pilot_does_not_answer_lapses(clock: FakeClock) -> None:
    a = AccessControl(AccessConfig(token=TOKEN, handover_timeout=20.0), clock=clock)
    for c in (1, 2):
        a.connect(c)
    a.request_control(1, TOKEN)
    seen = []
    a.add_listener(lambda st: seen.append(st.pending))
    assert a.request_control(2, TOKEN) is False
    clock.advance(19.9)
    assert a.expire() is None and a.pending == 2
    clock.advance(0.2)
    assert a.pending is None and a.state().pending is None  # judged by the clock, at once
    assert a.expire() == 2  # ... and the pages told
    assert seen == [2, None]
    assert a.expire() is None and seen == [2, None]
    with pytest.raises(AccessDenied, match="has not asked"):
        a.hand_over(1, 2)
    assert a.request_control(2, TOKEN) is False  # asking again starts a new wait
    clock.advance(10.0)
    a.hand_over(1, 2)
    assert a.pilot == 2


def test_a_lapsed_request_cannot_be_accepted_even_before_it_is_cleared(clock: FakeClock) -> None:
    a = AccessControl(AccessConfig(token=TOKEN, handover_timeout=5.0), clock=clock)
    for c in (1, 2):
        a.connect(c)
    a.request_control(1, TOKEN)
    a.request_control(2, TOKEN)
    clock.advance(5.0)
    with pytest.raises(AccessDenied, match="lapsed"):
        a.hand_over(1, 2)
    assert a.pilot == 1 and a.pending is None


def test_releasing_control_drops_the_request_made_to_the_pilot(access: AccessControl) -> None:
    access.request_control(1, TOKEN)
    access.request_control(2, TOKEN)
    access.release(1)
    assert access.pilot is None and access.pending is None


def test_a_token_with_surrounding_spaces_is_refused_naming_the_key() -> None:
    from ucat_console.config import AppConfig

    with pytest.raises(ValueError, match="surrounding"):
        AccessConfig(token=f" {TOKEN}")
    with pytest.raises(ValueError, match=r"access\.token: .*surrounding") as e:
        AppConfig.from_dict({"access": {"token": f"{TOKEN}\t"}})
    assert TOKEN not in str(e.value)  # the error does not show the secret


def test_the_pages_token_is_compared_without_its_surrounding_spaces(access: AccessControl) -> None:
    assert access.request_control(1, f"  {TOKEN}\n") is True


def test_an_oversized_token_is_a_wrong_token(access: AccessControl) -> None:
    with pytest.raises(AccessDenied, match="wrong"):
        access.request_control(1, TOKEN + "x" * 5000)


def test_failures_spread_beyond_the_window_do_not_lock(access: AccessControl, clock: FakeClock) -> None:
    for _ in range(4):
        with pytest.raises(AccessDenied, match="wrong"):
            access.request_control(2, "guess")
        clock.advance(20.0)  # only two failures ever fall within 30 s
    assert access.request_control(2, TOKEN) is True


def test_listeners_see_every_change(access: AccessControl) -> None:
    seen = []
    access.add_listener(lambda st: seen.append(st.pilot))
    access.request_control(1, TOKEN)
    access.disconnect(1)
    assert seen == [1, None]
