// The web view of a line (`supervisor web --line`) read as its page reads it, for the
// integration tests (tests/tests/it/line.rs): the list of cells, one cell's view, a cell name
// that is no name, and the e-stop button (which only a cell's own view may press).
//
//   node line_page.mjs http://127.0.0.1:PORT CELL
//
// Prints one JSON object: "list" (the first message without ?cell=), "cell" (the first ten
// messages of ?cell=CELL), "unknown" (?cell= with a name that is none), "estop" (the POST's
// status and words).
import { WebSocket } from "ws";

const [base, cell] = process.argv.slice(2);
const read = (path, n, seconds) =>
  new Promise((resolve) => {
    const got = [];
    const ws = new WebSocket(base.replace(/^http/, "ws") + path);
    let over = false;
    const done = () => {
      if (over) return;
      over = true;
      try { ws.close(); } catch {}
      resolve(got);
    };
    ws.on("message", (d) => {
      got.push(JSON.parse(d.toString()));
      if (got.length >= n) done();
    });
    ws.on("unexpected-response", (_req, res) => {
      let body = "";
      res.on("data", (c) => (body += c));
      res.on("end", () => { got.push({ refused: res.statusCode, why: body }); done(); });
    });
    ws.on("error", (e) => { got.push({ error: String(e) }); done(); });
    setTimeout(done, seconds * 1000);
  });
const list = await read("/ws", 1, 20);
const view = await read(`/ws?cell=${encodeURIComponent(cell)}`, 10, 20);
const unknown = await read("/ws?cell=Not%20a%20name", 1, 5);
const r = await fetch(`${base}/api/estop?cell=${encodeURIComponent(cell)}`, {
  method: "POST",
  headers: { "X-Rtc-Request": "1" },
});
console.log(JSON.stringify({ list, cell: view, unknown, estop: { status: r.status, text: await r.text() } }));
process.exit(0);
