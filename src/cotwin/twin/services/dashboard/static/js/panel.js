// The command panel, built from the twin's command events (describe.py: commands.events): one form
// per event with an input per value port. Sent through the server, which publishes on the twin's
// broker as an external publisher does; when the twin's commands come from a plan the panel says so
// and only lists the plan. For a cell of several robots (commands.robots), a chooser names the robot each
// command goes to (its own routing key).

function h(tag, attrs = {}, ...children) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (k === "class") e.className = v; else if (v !== false && v !== null) e.setAttribute(k, v === true ? "" : v);
  }
  e.append(...children);
  return e;
}

export function buildPanel(container, caption, sentLog, commands) {
  container.replaceChildren();
  const live = commands.source === "rabbitmq";
  if (commands.source === "plan") {
    caption.textContent = "from the plan";
    const list = h("ol", { class: "log" });
    for (const c of commands.planned) {
      list.append(h("li", {}, `t = ${c.time.toFixed(2)} s  ` +
        Object.entries(c.values).map(([k, v]) => `${k}=${v}`).join(" ")));
    }
    container.append(h("div", { class: "note-box", id: "command-source" },
      `This twin's commands come from its plan (${commands.plan}); the panel cannot command it.`), list);
  } else if (commands.source === "none") {
    caption.textContent = "none";
    container.append(h("div", { class: "note-box", id: "command-source" }, "This twin takes no commands."));
    return;
  } else {
    const b = commands.broker;
    caption.textContent = `RabbitMQ ${b.exchange} → ${b.to_cosim}`;
  }
  const robots = live && commands.robots ? commands.robots : null;
  let chooser = null;
  if (robots) {
    chooser = h("select", { id: "command-robot", "aria-label": "robot" },
      ...robots.map((name) => h("option", { value: name }, name)));
    container.append(h("label", { class: "robot-choice" }, "robot ", chooser));
  }
  for (const ev of commands.events) {
    const form = h("form", { class: "command", "data-event": ev.name });
    form.append(h("strong", {}, ev.name));
    for (const v of ev.values) {
      const attrs = { name: v.port, "aria-label": v.label, disabled: !live };
      const input = v.type === "Boolean" ? h("input", { type: "checkbox", ...attrs })
        : v.literals ? h("select", attrs, ...v.literals.map((name) => h("option", { value: name }, name)))
        : h("input", { type: "number", step: v.type === "Integer" ? "1" : "any", value: "0", required: true,
          min: v.min ?? false, ...attrs });
      form.append(h("label", {}, v.label, input));
    }
    const button = h("button", { type: "submit", disabled: !live }, "Send");
    form.append(button);
    form.addEventListener("submit", async (e) => {
      e.preventDefault();
      const values = {};
      for (const v of ev.values) {
        const input = form.elements[v.port];
        values[v.port] = v.type === "Boolean" ? input.checked : v.literals ? input.value : Number(input.value);
      }
      const robot = chooser ? chooser.value : null;
      const text = `${robot ? robot + "." : ""}${ev.name} ` +
        Object.entries(values).map(([k, x]) => `${k.split("_").pop()}=${x}`).join(" ");
      const item = h("li", { class: "pending" }, `${new Date().toLocaleTimeString()} ${text}: sending`);
      sentLog.prepend(item);
      try {
        const r = await fetch("/api/command", { method: "POST", headers: { "Content-Type": "application/json" },
          body: JSON.stringify(robot ? { robot, event: ev.name, values } : { event: ev.name, values }) });
        const answer = await r.json();
        item.className = !r.ok ? "error" : answer.applied ? "confirmed" : "queued";
        item.textContent = `${new Date().toLocaleTimeString()} ${text}: ` + (!r.ok ? answer.error
          : answer.applied ? `applied in the step to t = ${Number(answer.applied.time).toFixed(2)} s`
          : answer.place !== undefined ? `queued by the twin, ${answer.place} before it`
          : answer.twin_ready ? "accepted, not applied yet" : "queued until the twin is ready");
      } catch (err) {
        item.className = "error";
        item.textContent = `${text}: ${err}`;
      }
    });
    container.append(form);
  }
}
