# The R Luminescence package's fit_CWCurve on its own example decay curves:
# writes each curve as a phos CSV (t,value) and one summary row per curve
# with the number of components it chose (F-test), its residual sum of
# squares and its time per fit (median of 5 timed runs after one warm-up).
# Usage: Rscript fit_cwcurve.R OUTDIR
suppressMessages(library(Luminescence))
args <- commandArgs(trailingOnly = TRUE)
out <- args[1]
dir.create(out, showWarnings = FALSE, recursive = TRUE)

curves <- list()
data(ExampleData.CW_OSL_Curve, envir = environment())
curves[["CW_OSL_Curve"]] <- ExampleData.CW_OSL_Curve
data(ExampleData.XSYG, envir = environment())
osl <- get_RLum(OSL.SARMeasurement$Sequence.Object, recordType = "OSL (UVVIS)", drop = FALSE)
for (i in seq_along(osl@records)) {
  m <- osl@records[[i]]@data
  curves[[sprintf("XSYG_OSL_%02d", i)]] <- data.frame(x = m[, 1], y = m[, 2])
}

rows <- list()
for (name in names(curves)) {
  values <- curves[[name]]
  write.csv(data.frame(t = values$x, value = values$y), file.path(out, paste0(name, ".csv")),
            row.names = FALSE, quote = FALSE)
  fit <- function() suppressWarnings(fit_CWCurve(values = values, n.components.max = 4, plot = FALSE,
                                                 output.terminal = FALSE, verbose = FALSE))
  result <- tryCatch(fit(), error = function(e) NULL)
  if (is.null(result) || is.null(result@data$fit)) {
    rows[[name]] <- data.frame(curve = name, points = nrow(values), n_components = NA, rss = NA, seconds = NA)
    next
  }
  times <- numeric(5)
  for (k in 1:5) times[k] <- system.time(fit())[["elapsed"]]
  rows[[name]] <- data.frame(curve = name, points = nrow(values), n_components = result@data$data$n.components,
                             rss = deviance(result@data$fit), seconds = median(times))
}
write.csv(do.call(rbind, rows), file.path(out, "luminescence.csv"), row.names = FALSE, quote = FALSE)
