// rangekit ui: the one events client. The scan job's events (its session's events.jsonl) over /ws/events, opened
// with a single-use ticket; every message handed to the listeners. A socket that closes is opened again, asking
// for the same session from the offset the page got to: nothing twice, nothing missed. A tab left open across a
// server restart stops trying once the new server refuses its token (the banner says to open the new URL).
"use strict";

const rangekitEvents = (() => {
  const listeners = [];
  const client = {
    session: undefined, start: 0, offset: 0, received: 0, connects: [], socket: null,
    // fn({kind: "job", session, start, launch, fresh}) when the followed job changes (fresh: another session, start
    // over), fn({kind: "event", event, offset, current}) for each event (current: of the job launched last).
    listen(fn) { listeners.push(fn); },
  };
  const tell = (message) => { for (const fn of listeners) fn(message); };

  async function connect() {
    const t = await ticket("/ws/events");
    if (!t) { if (serverMayAnswer()) setTimeout(connect, 1000); return; }
    const query = new URLSearchParams({ ticket: t });
    if (client.session) { query.set("session", client.session); query.set("offset", String(client.offset)); }
    client.connects.push({ session: client.session ?? null, offset: client.offset });
    const ws = new WebSocket(`ws://${location.host}/ws/events?${query}`);
    client.socket = ws;
    ws.onmessage = (m) => {
      const msg = JSON.parse(m.data);
      if ("session" in msg) {
        const fresh = msg.session !== client.session;
        Object.assign(client, { session: msg.session, start: msg.start, offset: msg.offset });
        tell({ kind: "job", session: msg.session, start: msg.start, launch: msg.launch, fresh });
        // ended with no folder for its events (refused before it made it): its exit comes with the job
        if (msg.exited) tell({ kind: "event", event: msg.exited, offset: msg.offset, current: true });
        return;
      }
      client.offset = msg.offset; client.received += 1;
      tell({ kind: "event", event: msg.event, offset: msg.offset, current: msg.offset > client.start });
    };
    ws.onclose = () => { if (client.socket === ws) client.socket = null; setTimeout(connect, 1000); };
  }
  connect();
  return client;
})();
window.rangekitEvents = rangekitEvents;
