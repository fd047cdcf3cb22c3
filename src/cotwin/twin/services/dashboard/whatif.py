"""The page's "what if" button: a what-if request to the live twin's WhatIfService over the broker, as any
requester sends it (cotwin.twin.services.whatif: a JSON request on the twin's topic exchange, routing key
`twin.whatif`, with `reply_to` and `correlation_id`), and the answer it gets back. The plan is checked
with the service's own parser first, so a mistyped plan is refused at once with the place it is wrong.
"""

from __future__ import annotations

import json
import time as wallclock
import uuid

import pika

from .... import safejson
from ....diagnostics import CotwinError
from ....mapping.amqp import connect, declare_exchange
from ...assembly.rabbitmq import EVENTS

MAX_ANSWER = 64 << 20  # bytes of a what-if answer (a trajectory of an hour at 1 ms is about 50 MiB)


def check_request(body: dict, program) -> dict:
    """{plan, horizon} from the page, checked; CotwinError saying what is wrong."""
    from ..whatif import plan_from_json

    shape = "a what-if request is {\"plan\": [{time, event, args}, ...], \"horizon\": seconds}"
    if not isinstance(body, dict):
        raise CotwinError(shape)
    unknown = sorted(set(body) - {"plan", "horizon"})
    if unknown:
        raise CotwinError(f"unknown key {', '.join(repr(k[:40]) for k in unknown[:10])}: {shape}")
    plan_from_json(body.get("plan"), program)  # the service's own checks
    horizon = body.get("horizon", 30.0)
    if isinstance(horizon, bool) or not isinstance(horizon, (int, float)) or not 0 < horizon <= 3600:
        raise CotwinError("horizon must be a number of seconds in (0, 3600]")
    return {"plan": body["plan"], "horizon": float(horizon)}


def ask(url: str, exchange: str, request: dict, timeout: float = 120.0, routing_key: str = "twin.whatif",
        cancel=None) -> dict:
    """Publish `request` to the twin's what-if service and wait (at most `timeout`, and no longer than
    the threading.Event `cancel` stays clear) for its answer."""
    try:
        connection = connect(url, "cotwin dashboard what-if")
    except (pika.exceptions.AMQPError, OSError) as err:
        raise CotwinError(f"what-if: cannot reach the broker ({type(err).__name__})") from None
    try:
        channel = connection.channel()
        declare_exchange(channel, exchange, "topic", url, EVENTS)
        reply = channel.queue_declare("", exclusive=True, auto_delete=True).method.queue
        correlation = uuid.uuid4().hex
        answer: dict = {}

        def on_reply(ch, method, props, body) -> None:
            if props.correlation_id == correlation:
                answer["body"] = body

        channel.basic_consume(reply, on_reply, auto_ack=True)
        channel.basic_publish(exchange, routing_key, json.dumps(request).encode(),
                              pika.BasicProperties(reply_to=reply, correlation_id=correlation,
                                                   content_type="application/json"))
        deadline = wallclock.monotonic() + timeout
        while "body" not in answer:
            left = deadline - wallclock.monotonic()
            if left <= 0:
                raise CotwinError(f"what-if: no answer within {timeout:g} s (is the twin still running, with --whatif?)")
            if cancel is not None and cancel.is_set():
                raise CotwinError("what-if: the dashboard is stopping")
            connection.process_data_events(time_limit=min(left, 0.1))
        try:
            found = safejson.loads_object(answer["body"], MAX_ANSWER)
        except safejson.Refused as err:
            raise CotwinError(f"what-if: the service's answer is refused: {err}") from None
        return found
    finally:
        try:
            connection.close()
        except Exception:  # noqa: BLE001 - closing a dead link
            pass
