// The REST API as the console uses it: every call carries the bearer token the user entered,
// and a failure carries the server's own status and message so the page can show them as they are.

const TOKEN_KEY = "segsplat.token";

export class ApiFailure extends Error {
  constructor(status, code, message) {
    super(message);
    this.status = status;
    this.code = code;
  }
  // "409 conflict: the scene has a running job" - what the page shows.
  describe() {
    return this.status ? `${this.status} ${this.code}: ${this.message}` : this.message;
  }
}

export function token() {
  return localStorage.getItem(TOKEN_KEY) || "";
}

export function setToken(value) {
  if (value) localStorage.setItem(TOKEN_KEY, value);
  else localStorage.removeItem(TOKEN_KEY);
}

// Listeners told when the server refuses the token, so the page can ask for another.
const unauthorizedListeners = [];
export function onUnauthorized(listener) {
  unauthorizedListeners.push(listener);
}

function authHeaders(extra = {}) {
  const headers = { ...extra };
  if (token()) headers.Authorization = `Bearer ${token()}`;
  return headers;
}

async function failureFrom(response) {
  let code = response.statusText || "error";
  let message = `the server answered ${response.status}`;
  try {
    const body = await response.json();
    if (body && body.error) {
      code = body.error.code || code;
      message = body.error.message || message;
    }
  } catch {
    // Not the JSON error envelope (a proxy's page, say): keep the status line.
  }
  const failure = new ApiFailure(response.status, code, message);
  if (response.status === 401) unauthorizedListeners.forEach((listener) => listener(failure));
  return failure;
}

// A GET with the token whatever the answer (no ApiFailure): for /readyz, whose 503 carries the
// same body as its 200.
export function fetchWithToken(path) {
  return fetch(path, { headers: authHeaders() });
}

// A request to the API; resolves to the response, or throws ApiFailure for a non-2xx answer.
export async function request(path, { method = "GET", json, body, headers, signal } = {}) {
  const init = { method, headers: authHeaders(headers), signal };
  if (json !== undefined) {
    init.body = JSON.stringify(json);
    init.headers["Content-Type"] = "application/json";
  } else if (body !== undefined) {
    init.body = body;
  }
  let response;
  try {
    response = await fetch(path, init);
  } catch (error) {
    if (error.name === "AbortError") throw error;
    throw new ApiFailure(0, "network", `could not reach the server: ${error.message}`);
  }
  if (!response.ok) throw await failureFrom(response);
  return response;
}

export async function getJson(path, options) {
  return (await request(path, options)).json();
}

export async function sendJson(method, path, json) {
  return (await request(path, { method, json })).json();
}

export async function getBytes(path) {
  return (await request(path)).arrayBuffer();
}

// Uploads a file with a progress callback (fetch cannot report upload progress; XHR can).
export function upload(path, file, onProgress) {
  return new Promise((resolve, reject) => {
    const xhr = new XMLHttpRequest();
    xhr.open("POST", path);
    for (const [name, value] of Object.entries(authHeaders())) xhr.setRequestHeader(name, value);
    xhr.setRequestHeader("Content-Type", file.type || "application/octet-stream");
    xhr.upload.onprogress = (event) => {
      if (event.lengthComputable) onProgress(event.loaded / event.total);
    };
    xhr.onerror = () => reject(new ApiFailure(0, "network", "the upload was interrupted"));
    xhr.onload = () => {
      let body = null;
      try {
        body = JSON.parse(xhr.responseText);
      } catch {
        body = null;
      }
      if (xhr.status >= 200 && xhr.status < 300) return resolve(body);
      const error = body && body.error ? body.error : {};
      const failure = new ApiFailure(
        xhr.status,
        error.code || xhr.statusText || "error",
        error.message || `the server answered ${xhr.status}`,
      );
      if (xhr.status === 401) unauthorizedListeners.forEach((listener) => listener(failure));
      reject(failure);
    };
    xhr.send(file);
  });
}

// Server-Sent Events with the bearer token (EventSource cannot send headers): reads the stream
// with fetch and calls onEvent(kind, data) per event until the stream ends or signal aborts.
export async function followEvents(path, onEvent, signal) {
  const response = await request(path, { headers: { Accept: "text/event-stream" }, signal });
  const reader = response.body.pipeThrough(new TextDecoderStream()).getReader();
  let buffered = "";
  for (;;) {
    const { value, done } = await reader.read();
    if (done) return;
    buffered += value;
    let boundary;
    while ((boundary = buffered.indexOf("\n\n")) >= 0) {
      const block = buffered.slice(0, boundary);
      buffered = buffered.slice(boundary + 2);
      let kind = "message";
      const data = [];
      for (const line of block.split("\n")) {
        if (line.startsWith("event:")) kind = line.slice(6).trim();
        else if (line.startsWith("data:")) data.push(line.slice(5).trimStart());
      }
      if (data.length) onEvent(kind, JSON.parse(data.join("\n")));
    }
  }
}

// Saves what an authenticated GET returns as a file (a plain link could not carry the token).
export async function download(path, fileName) {
  const blob = await (await request(path)).blob();
  const url = URL.createObjectURL(blob);
  const anchor = document.createElement("a");
  anchor.href = url;
  anchor.download = fileName;
  document.body.append(anchor);
  anchor.click();
  anchor.remove();
  setTimeout(() => URL.revokeObjectURL(url), 10_000);
}
