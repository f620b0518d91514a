// The sign-in form: the name and password to /signin; a session cookie comes back, then the
// page itself.
"use strict";

document.getElementById("signin").addEventListener("submit", async (event) => {
  event.preventDefault();
  const why = document.getElementById("why");
  why.textContent = "signing in…";
  try {
    const reply = await fetch("signin", {
      method: "POST", headers: {"Content-Type": "application/json"},
      body: JSON.stringify({user: document.getElementById("user").value,
                            password: document.getElementById("password").value})});
    if (reply.ok) {
      window.location.reload();
      return;
    }
    why.textContent = (await reply.json()).detail;
  } catch (err) {
    why.textContent = `no answer from the page's server (${err})`;
  }
});
