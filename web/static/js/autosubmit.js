// Forms marked data-autosubmit reload as soon as a select changes; the submit button stays
// for keyboard users and for browsers without scripts.
"use strict";
document.querySelectorAll("form[data-autosubmit]").forEach((form) => {
  form.querySelectorAll("select").forEach((select) => {
    select.addEventListener("change", () => form.requestSubmit());
  });
});
