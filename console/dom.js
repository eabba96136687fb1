// Small DOM helpers shared by the pages.

export const $ = (id) => document.getElementById(id);

// An element with attributes and children; strings become text (never HTML).
export function el(tag, attributes = {}, ...children) {
  const node = document.createElement(tag);
  for (const [name, value] of Object.entries(attributes)) {
    if (value === undefined || value === null || value === false) continue;
    if (name === "class") node.className = value;
    else if (name.startsWith("on")) node.addEventListener(name.slice(2), value);
    else node.setAttribute(name, value === true ? "" : value);
  }
  for (const child of children.flat()) {
    if (child === null || child === undefined) continue;
    node.append(child instanceof Node ? child : document.createTextNode(String(child)));
  }
  return node;
}

// Shows a message in an error element, or hides it for an empty one.
export function showError(element, message) {
  element.textContent = message || "";
  element.hidden = !message;
}

export function describeError(error) {
  return typeof error.describe === "function" ? error.describe() : String(error.message || error);
}

export function fillFacts(list, facts) {
  list.replaceChildren(...facts.flatMap(([name, value]) => [el("dt", {}, name), el("dd", {}, value)]));
}

export function formatNumber(value, digits = 3) {
  if (value === undefined || value === null || Number.isNaN(value)) return "-";
  return Number(value).toLocaleString(undefined, { maximumFractionDigits: digits });
}

export function formatSeconds(seconds) {
  if (seconds === undefined || seconds === null || !Number.isFinite(seconds)) return "-";
  const whole = Math.max(0, Math.round(seconds));
  const minutes = Math.floor(whole / 60);
  return minutes ? `${minutes} min ${whole % 60} s` : `${whole} s`;
}

// A CSS colour from 0..1 RGB.
export function cssColor(rgb) {
  const channel = (value) => Math.round(Math.min(1, Math.max(0, value)) * 255);
  return `rgb(${channel(rgb[0])}, ${channel(rgb[1])}, ${channel(rgb[2])})`;
}

// Table rows that act as buttons: Enter and Space activate them, like a click.
export function activatable(row, onActivate) {
  row.tabIndex = 0;
  row.addEventListener("click", onActivate);
  row.addEventListener("keydown", (event) => {
    if (event.target !== row) return;
    if (event.key === "Enter" || event.key === " ") {
      event.preventDefault();
      onActivate(event);
    }
  });
  return row;
}
