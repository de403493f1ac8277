// rangekit ui: the one events client, two sockets, each opened with a single-use ticket.
// - /ws/events: the scan job's events (its session's events.jsonl); every message handed to the listen() listeners.
//   A socket that closes is opened again, asking for the same session from the offset the page got to: nothing
//   twice, nothing missed.
// - /ws/jobs: the other jobs' state (check, calibrate, recorded, register) and the rig's, sent by the server when
//   they change; each handed to its onJob(name) / onRig() listeners, and kept (jobs[name], rig) for a page shown
//   later. A socket that closes is opened again and is sent every state again.
// No timer asks the server anything: the pages change when a message comes. A tab left open across a server restart
// stops trying once the new server refuses its token (the banner says to open the new URL).
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

  // -- /ws/jobs: each job's state and the rig's, as the server sends them
  const jobListeners = {}, rigListeners = [];
  Object.assign(client, {
    jobs: {}, rig: null, jobConnects: 0, jobMessages: 0, jobSocket: null,
    // fn(snapshot) now with the last state known (if any) and whenever job `name` changes (check, calibrate, ...).
    onJob(name, fn) {
      (jobListeners[name] ||= []).push(fn);
      if (client.jobs[name]) fn(client.jobs[name]);
    },
    // fn(status) now with the last status known (if any) and whenever the rig's changes (GET /api/status's body).
    onRig(fn) { rigListeners.push(fn); if (client.rig) fn(client.rig); },
  });

  async function connectJobs() {
    const t = await ticket("/ws/jobs");
    if (!t) { if (serverMayAnswer()) setTimeout(connectJobs, 1000); return; }
    client.jobConnects += 1;
    const ws = new WebSocket(`ws://${location.host}/ws/jobs?ticket=${encodeURIComponent(t)}`);
    client.jobSocket = ws;
    ws.onmessage = (m) => {
      const msg = JSON.parse(m.data);
      client.jobMessages += 1;
      if ("rig" in msg) { client.rig = msg.rig; for (const fn of rigListeners) fn(msg.rig); return; }
      client.jobs[msg.job] = msg.snapshot;
      for (const fn of jobListeners[msg.job] || []) fn(msg.snapshot);
    };
    ws.onclose = () => { if (client.jobSocket === ws) client.jobSocket = null; setTimeout(connectJobs, 1000); };
  }
  connectJobs();
  return client;
})();
window.rangekitEvents = rangekitEvents;
