# The R Luminescence package's fit_CWCurve on its own example CW-OSL curves:
# writes each curve as a phos CSV (t,value) and one summary row per curve
# with the number of components it chose (its F-test, up to 3), its residual
# sum of squares and its time per fit in process (median of 5 timed runs after
# one warm-up).
# Curves (62): ExampleData.CW_OSL_Curve; the 14 OSL curves of ExampleData.XSYG;
# and from ExampleData.BINfileData (CWOSL.SAR.Data, 24 aliquots) the first two
# OSL curves of each aliquot, its natural signal Ln and test dose Tn, less
# aliquot 1's Ln, which is ExampleData.CW_OSL_Curve itself.
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
data(ExampleData.BINfileData, envir = environment())
meta <- CWOSL.SAR.Data@METADATA
for (position in sort(unique(meta$POSITION))) {
  records <- which(meta$LTYPE == "OSL" & meta$POSITION == position)[1:2]
  for (j in seq_along(records)) {
    r <- records[j]
    n <- meta$NPOINTS[r]
    # Channel k (1..n) ends at k * HIGH / n seconds of stimulation.
    t <- seq_len(n) * meta$HIGH[r] / n
    y <- as.numeric(CWOSL.SAR.Data@DATA[[r]])
    # ExampleData.CW_OSL_Curve is aliquot 1's Ln: each curve once.
    if (any(vapply(curves, function(c) length(c$y) == length(y) && all(c$y == y), logical(1)))) next
    curves[[sprintf("BIN_pos%02d_%s", position, c("Ln", "Tn")[j])]] <- data.frame(x = t, y = y)
  }
}

rows <- list()
for (name in names(curves)) {
  values <- curves[[name]]
  write.csv(data.frame(t = values$x, value = values$y), file.path(out, paste0(name, ".csv")),
            row.names = FALSE, quote = FALSE)
  fit <- function() suppressWarnings(fit_CWCurve(values = values, n.components.max = 3, plot = FALSE,
                                                 output.terminal = FALSE, verbose = FALSE))
  result <- tryCatch(fit(), error = function(e) NULL)
  times <- numeric(5)
  for (k in 1:5) times[k] <- system.time(tryCatch(fit(), error = function(e) NULL))[["elapsed"]]
  if (is.null(result) || is.null(result@data$fit)) {
    rows[[name]] <- data.frame(curve = name, points = nrow(values), n_components = NA, rss = NA,
                               seconds = median(times))
    next
  }
  rows[[name]] <- data.frame(curve = name, points = nrow(values), n_components = result@data$data$n.components,
                             rss = deviance(result@data$fit), seconds = median(times))
}
write.csv(do.call(rbind, rows), file.path(out, "luminescence.csv"), row.names = FALSE, quote = FALSE)
