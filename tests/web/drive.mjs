// Drives `supervisor web`'s page in a real headless Chromium for tests/tests/it/web.rs.
//   node drive.mjs URL
// Reads one command per line on stdin and answers one JSON line on stdout each:
//   sample SECONDS [MOVING]   what the page drew meanwhile: [{t, drawn, tool, joints, line,
//                    state}], every 100 ms; with MOVING, on past SECONDS (at most 60 s more)
//                    until MOVING of them saw a program moving (state 1): a browser held off
//                    the CPU takes fewer samples in the same time
//   shot FILE        a screenshot
//   click ID         clicks a button (estop, reset, start)
//   until EXPR       waits (up to 60 s) until the expression holds in the page, e.g. rtc.estop
//   eval EXPR        the expression's value in the page, e.g. rtc.path
//   goto URL         another page (its errors from then on)
//   quit
import { chromium } from 'playwright-core';
import readline from 'node:readline';

const url = process.argv[2];
const browser = await chromium.launch({
  executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
  args: ['--no-sandbox', '--use-angle=swiftshader', '--enable-unsafe-swiftshader'],
});
const page = await browser.newPage({ viewport: { width: 1024, height: 640 } });
const errors = [];
page.on('pageerror', (e) => errors.push(String(e)));
page.on('console', (m) => { if (m.type() === 'error' && !m.text().includes('favicon')) errors.push(m.text()); });
await page.goto(url);
await page.waitForFunction(() => window.rtc && window.rtc.frames > 3 && window.rtc.drawn, null, { timeout: 60000 });
const say = (o) => process.stdout.write(JSON.stringify(o) + '\n');
say({ ready: true, errors });

for await (const line of readline.createInterface({ input: process.stdin })) {
  const [cmd, ...rest] = line.trim().split(' ');
  const arg = rest.join(' ');
  try {
    if (cmd === 'sample') {
      const out = [];
      const start = Date.now();
      const end = start + Number(rest[0]) * 1000;
      const moving = Number(rest[1] ?? 0);
      const enough = () => out.filter((s) => s.state === 1).length >= moving;
      while (Date.now() < end || (!enough() && Date.now() < end + 60000)) {
        out.push(await page.evaluate(() => ({
          t: rtc.last?.t, drawn: rtc.drawn, tool: rtc.last?.tool, joints: rtc.last?.joints,
          line: rtc.last?.program?.line, state: rtc.last?.program?.state,
        })));
        await new Promise((r) => setTimeout(r, 100));
      }
      say({ samples: out, errors });
    } else if (cmd === 'shot') {
      await page.screenshot({ path: arg });
      say({ shot: arg });
    } else if (cmd === 'click') {
      await page.click(`#${arg}`);
      say({ clicked: arg });
    } else if (cmd === 'until') {
      await page.waitForFunction(arg, null, { timeout: 60000, polling: 100 });
      say({ held: arg, banner: await page.textContent('#banner'), answer: await page.textContent('#answer') });
    } else if (cmd === 'eval') {
      say({ value: await page.evaluate(arg) });
    } else if (cmd === 'goto') {
      await page.goto(arg);
      say({ at: arg, errors });
    } else if (cmd === 'quit') {
      say({ bye: true, errors });
      break;
    } else {
      say({ error: `unknown command ${cmd}` });
    }
  } catch (e) {
    say({ error: String(e), banner: await page.textContent('#banner').catch(() => null) });
  }
}
await browser.close();
