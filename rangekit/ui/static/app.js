// rangekit ui: what every page shares besides the API and events clients (api.js, events.js): the page switch.
// Each page is its own script (live, check, calibrate, scan, sessions, register).
"use strict";

// The hash names the section shown names the section shown (one that names none: the first page)
function showPage() {
  const pages = [...document.querySelectorAll("main > section")].map((sec) => sec.id);
  const asked = location.hash.slice(1), name = pages.includes(asked) ? asked : pages[0];
  for (const sec of document.querySelectorAll("main > section")) sec.hidden = sec.id !== name;
  for (const a of document.querySelectorAll("header nav a")) a.classList.toggle("on", a.getAttribute("href") === `#${name}`);
}
window.addEventListener("hashchange", showPage);
showPage();

